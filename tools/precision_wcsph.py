"""Single against double precision in mode wcsph_biot: the same cases at `precision: f32` and `f64`, each
measured against its reference and against the other precision. Writes the section "Precision" of
docs/performance_wcsph.md and docs/precision_wcsph.json.

    python tools/precision_wcsph.py [--case hydrostatic dambreak terzaghi dupuit] [--precision f64 f32]
                                    [--hydrostatic-time 10] [--src CHECKOUT] [--label NAME] [--out FILE]

Cases (every run one process through the command line, one thread, TI_CPU_MAX_NUM_THREADS=1):
- hydrostatic: configs/hydrostatic.yaml in mode wcsph_biot (0.4 x 0.3 m of water, dx 1 cm) for
  `--hydrostatic-time` seconds: floor pressure against rho g H (the bottom row extrapolated to the floor,
  as tools/validate.py), largest speed over the second half against sqrt(g H), volume drift, and how far
  the water particles have moved from their start (RMS and largest, in dx): at rest they should not move.
- dambreak: configs/dambreak_wcsph.yaml at dx a / 50 (5k particles) to T = t sqrt(2 g / a) = 3: the surge
  front Z = x_front / a against Martin & Moyce (1952, mean |Z / Z_exp - 1| for T in [1, 3]) and the largest
  difference between the precisions' fronts over the frames.
- terzaghi: configs/consolidation.yaml (dx 1 cm, 5 columns): the largest isochrone error |u_e / u0 - exact|
  at Tv 0.05, 0.1, 0.2, 0.5 (taichi_sph/wcsph/consolidation.py; each run has its twin without the excess).
- dupuit: configs/levee_seepage.yaml (dx 1 cm, 2 s): discharge over 0.3-2 s against Dupuit's
  (taichi_sph/wcsph/dupuit.py).
Each row also gives the CPU seconds of its process(es) (one thread; other load on the machine disturbs CPU
time much less than wall time), so the f32 / f64 CPU ratio of a case is a speed measure too.

`--src` runs the package and configs of another checkout (e.g. the commit before a change of the
precision scheme), `--label` names it in the table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

G = 9.81
RHO = 1000.0
HYDRO_H = 0.30
DAM_A = 1.0
DAM_DX = 0.02
REUSE = False
TERZAGHI = {"u0": 500.0, "half": 0.4, "soil_top": 0.2, "k": 5e-3, "E": 1.0e6, "nu": 0.3}


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(src: Path, config: str, out: Path, sets: list[str], args=()) -> dict:
    """One CLI run with the code of `src`, one thread; its rc, message, wall and CPU seconds (kept beside the
    run file as OUT.run.json: with --reuse a run whose file and record exist is not run again)."""
    from taichi_sph.cli_process import run_cli

    record = out.with_suffix(".run.json")
    if REUSE and out.exists() and record.exists():
        return json.loads(record.read_text())

    cmd = ["--config", str(src / config), "--out", str(out), "--no-progress", "--quiet", *args]
    for s in sets:
        cmd += ["--set", s]
    env = dict(os.environ, PYTHONPATH=str(src), TI_CPU_MAX_NUM_THREADS="1", TAICHI_SPH_PROGRESS="0")
    cpu0, load0 = children_cpu(), os.getloadavg()[0]
    res = run_cli(cmd, env=env, cwd=src)
    out_row = {
        "rc": res.rc,
        "message": res.message if res.rc else "",
        "wall_s": res.seconds,
        "cpu_s": children_cpu() - cpu0,
        "load": [load0, os.getloadavg()[0]],
    }
    if res.rc:
        print(res.output[-2000:], file=sys.stderr)
    else:
        record.write_text(json.dumps(out_row))
    return out_row


# ------------------------------------------------------------------------------------------- cases
def hydrostatic(src, prec, tmp, opts) -> dict:
    from taichi_sph.io.hdf5 import RunFile

    end = opts.hydrostatic_time
    out = tmp / f"hyd_{prec}.h5"
    row = run(
        src,
        "configs/hydrostatic.yaml",
        out,
        ["mode=wcsph_biot", f"precision={prec}", f"end_time={end:g}", f"output.every={end / 20:g}"],
    )
    if row["rc"]:
        return row
    with RunFile(out) as rf:
        water = rf.kind == 0
        x0 = rf.field("position", 0)[water]
        p_floor = []
        for i in range(rf.n_frames):
            f = rf.frame(i)
            z = f["position"][water][:, -1]
            p = f["pressure"][water]
            bottom = z < z.min() + 0.5 * rf.dx
            p_floor.append(float(np.mean(p[bottom] + RHO * G * z[bottom])) / (RHO * G * HYDRO_H) - 1)
        d = np.linalg.norm(rf.field("position", rf.n_frames - 1)[water] - x0, axis=1) / rf.dx
        diag = rf.diagnostics()
        late = diag["time"] >= 0.5 * diag["time"][-1]
        row.update(
            steps=int(len(diag["time"])),
            floor_pressure_end=p_floor[-1],
            floor_pressure_late=[min(p_floor[len(p_floor) // 2 :]), max(p_floor[len(p_floor) // 2 :])],
            speed_late=float(diag["max_speed"][late].max()) / math.sqrt(G * HYDRO_H),
            volume_drift=float(diag["water_volume"][-1] / diag["water_volume"][0] - 1),
            moved_rms_dx=float(np.sqrt(np.mean(d**2))),
            moved_max_dx=float(d.max()),
            positions=str(out),
        )
    return row


def dambreak(src, prec, tmp, opts) -> dict:
    from taichi_sph.io.hdf5 import RunFile

    end = 3.05 / math.sqrt(2 * G / DAM_A)
    out = tmp / f"dam_{prec}.h5"
    row = run(
        src,
        "configs/dambreak_wcsph.yaml",
        out,
        [f"precision={prec}", f"dx={DAM_DX:g}", f"end_time={end:.4g}", f"output.every={end / 40:.4g}"],
    )
    if row["rc"]:
        return row
    with RunFile(out) as rf:
        water = rf.kind == 0
        T = rf.times * math.sqrt(2 * G / DAM_A)
        Z = np.array(
            [
                rf.field("position", i)[water & rf.field("active", i)][:, 0].max() / DAM_A
                for i in range(rf.n_frames)
            ]
        )
        diag = rf.diagnostics()
    errs = []
    for name in ("martin_moyce_a1.125in_n2sq2", "martin_moyce_a2.25in_n2sq2"):
        lines = (ROOT / "tests" / "data" / f"{name}.csv").read_text().splitlines()
        ref = np.array([ln.split(",") for ln in lines if ln.strip() and not ln.startswith(("#", "T"))], float)
        sel = (ref[:, 0] >= 1.0) & (ref[:, 0] <= 3.0)
        errs.append(np.interp(ref[sel, 0], T, Z) / ref[sel, 1] - 1)
    row.update(
        steps=int(len(diag["time"])),
        T=T.tolist(),
        Z=Z.tolist(),
        martin_moyce_error=float(np.mean(np.abs(np.concatenate(errs)))),
        volume_drift=float(diag["water_volume"][-1] / diag["water_volume"][0] - 1),
    )
    return row


def terzaghi(src, prec, tmp, opts) -> dict:
    from taichi_sph.wcsph.consolidation import consolidation_coefficient, isochrone_errors

    sets = [f"precision={prec}", "dx=0.01"]
    out, base = tmp / f"tz_{prec}.h5", tmp / f"tz0_{prec}.h5"
    row = run(src, "configs/consolidation.yaml", out, sets)
    twin = run(
        src, "configs/consolidation.yaml", base, [*sets, "wcsph.soil.initial_excess_pressure.amplitude=0"]
    )
    if row["rc"] or twin["rc"]:
        return row if row["rc"] else twin
    row["cpu_s"] += twin["cpu_s"]
    row["wall_s"] += twin["wall_s"]
    row["load"][1] = twin["load"][1]
    tz = TERZAGHI
    cv = consolidation_coefficient(tz["k"], tz["E"], tz["nu"])
    errs = isochrone_errors(out, base, tz["u0"], tz["half"], tz["soil_top"], cv)
    row["isochrone_errors"] = {str(tv): e for tv, (e, _, _) in errs.items()}
    row["isochrone_error"] = max(e for e, _, _ in errs.values())
    return row


def dupuit(src, prec, tmp, opts) -> dict:
    from taichi_sph.wcsph.dupuit import discharge_ratio

    out = tmp / f"dupuit_{prec}.h5"
    row = run(src, "configs/levee_seepage.yaml", out, [f"precision={prec}", "dx=0.01", "end_time=2.0"])
    if row["rc"]:
        return row
    m = discharge_ratio(out, k=0.02, length=0.15, t_from=0.3)
    row.update(discharge_ratio=m["ratio"], h1=m["h1"], h2=m["h2"])
    return row


CASES = {"hydrostatic": hydrostatic, "dambreak": dambreak, "terzaghi": terzaghi, "dupuit": dupuit}


# ------------------------------------------------------------------------------------------- report
def _pct(x, digits=3) -> str:
    return f"{100 * x:+.{digits}f} %"


def _cpu(rows, prec) -> str:
    r = rows.get(prec, {})
    return f"{r['cpu_s']:.0f}" if "cpu_s" in r else ""


def markdown(res: dict, info: dict) -> str:
    lines = [
        f"Produced by `python tools/precision_wcsph.py` on {info['date']}: {info['machine']}; one thread "
        "per run; CPU s: the process's CPU time (other load disturbs it much less than wall time); load: the "
        "1-minute load average of the machine at the start / end of the run.",
        "",
    ]
    lines += [
        "| case | precision | measure | value | against the other precision | CPU s | load |",
        "|---|---|---|---|---|---|---|",
    ]
    f64 = {c: next((r for k, r in rows.items() if k.startswith("f64")), {}) for c, rows in res.items()}
    for case, rows in res.items():
        for prec, r in rows.items():
            load = f"{r['load'][0]:.1f} / {r['load'][1]:.1f}" if "load" in r else ""
            if r.get("rc"):
                lines.append(
                    f"| {case} | {prec} | failed | {r['message'][:120]} | | {_cpu(rows, prec)} | {load} |"
                )
                continue
            ref = f64[case] if not prec.startswith("f64") else {}
            vals = []
            if case == "hydrostatic":
                lo, hi = r["floor_pressure_late"]
                vals = [
                    (
                        f"floor pressure / rho g H - 1 at {info['hydrostatic_time']:g} s",
                        _pct(r["floor_pressure_end"]),
                        ref.get("floor_pressure_end"),
                        "floor_pressure_end",
                    ),
                    ("same, second half (min..max)", f"{_pct(lo)} .. {_pct(hi)}", None, None),
                    ("largest speed / sqrt(g H), second half", f"{r['speed_late']:.2e}", None, None),
                    ("water volume drift", _pct(r["volume_drift"], 4), None, None),
                    (
                        "particles moved from start, RMS / largest (dx)",
                        f"{r['moved_rms_dx']:.3f} / {r['moved_max_dx']:.3f}",
                        None,
                        None,
                    ),
                    ("steps", str(r["steps"]), None, None),
                ]
            elif case == "dambreak":
                diff = ""
                if "Z" in ref and len(ref["Z"]) == len(r["Z"]):
                    worst = np.max(np.abs(np.array(r["Z"]) / ref["Z"] - 1))
                    diff = f"front differs by at most {100 * worst:.2f} %"
                vals = [
                    (
                        "front: mean abs error against Martin & Moyce, T 1-3",
                        f"{100 * r['martin_moyce_error']:.2f} %",
                        diff,
                        None,
                    ),
                    ("front Z at T = 3", f"{r['Z'][-1]:.3f}", None, None),
                    ("water volume drift", _pct(r["volume_drift"], 4), None, None),
                    ("steps", str(r["steps"]), None, None),
                ]
            elif case == "terzaghi":
                per = ", ".join(f"{float(k):g}: {v:.4f}" for k, v in r["isochrone_errors"].items())
                vals = [
                    (
                        "largest isochrone error / u0",
                        f"{r['isochrone_error']:.4f}",
                        ref.get("isochrone_error"),
                        "isochrone_error",
                    ),
                    ("per Tv", per, None, None),
                ]
            elif case == "dupuit":
                vals = [
                    (
                        "q / q_Dupuit",
                        f"{r['discharge_ratio']:.4f}",
                        ref.get("discharge_ratio"),
                        "discharge_ratio",
                    ),
                    ("h1 / h2 (m)", f"{r['h1']:.4f} / {r['h2']:.4f}", None, None),
                ]
            for k, (what, val, other, key) in enumerate(vals):
                cmp = other if isinstance(other, str) else ""
                if key and other is not None and not isinstance(other, str):
                    cmp = f"{r[key] - other:+.2e}" if not prec.startswith("f64") else ""
                cpu = _cpu(rows, prec) if k == 0 else ""
                lines.append(
                    f"| {case if k == 0 else ''} | {prec if k == 0 else ''} | {what} | {val} | {cmp} | "
                    f"{cpu} | {load if k == 0 else ''} |"
                )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--precision", nargs="+", default=["f64", "f32"], choices=["f64", "f32"])
    ap.add_argument("--hydrostatic-time", type=float, default=10.0)
    ap.add_argument("--src", default=str(ROOT), help="checkout whose package and configs run")
    ap.add_argument("--label", default="")
    ap.add_argument("--keep", help="keep the run files in this folder")
    ap.add_argument("--reuse", action="store_true", help="with --keep: reuse the run files found there")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance_wcsph.md"))
    ap.add_argument("--json", default=str(ROOT / "docs" / "precision_wcsph.json"))
    ap.add_argument("--merge", nargs="+", help="only write the table from these result files (runs nothing)")
    opts = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from bench import machine
    from bench_wcsph import replace_section

    if opts.merge:
        res, info = {}, None
        for f in opts.merge:
            d = json.loads(Path(f).read_text())
            info = info or d["info"]
            for case, rows in d["results"].items():
                res.setdefault(case, {}).update(rows)
        Path(opts.json).write_text(json.dumps({"info": info, "results": res}, indent=1))
        replace_section(Path(opts.out), "precision", markdown(res, info))
        print(f"wrote {opts.out} (section precision) and {opts.json}")
        return 0
    global REUSE
    REUSE = opts.reuse
    src = Path(opts.src).resolve()
    res = {}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(opts.keep or tmpdir)
        tmp.mkdir(parents=True, exist_ok=True)
        for case in opts.case:
            res[case] = {}
            for prec in opts.precision:
                r = CASES[case](src, prec, tmp, opts)
                r.pop("positions", None)
                res[case][prec + (f", {opts.label}" if opts.label else "")] = r
                print(case, prec, {k: v for k, v in r.items() if k not in ("T", "Z")}, flush=True)
    info = {
        "machine": machine(),
        "date": time.strftime("%Y-%m-%d"),
        "label": opts.label,
        "hydrostatic_time": opts.hydrostatic_time,
    }
    Path(opts.json).write_text(json.dumps({"info": info, "results": res}, indent=1))
    replace_section(Path(opts.out), "precision", markdown(res, info))
    print(f"wrote {opts.out} (section precision) and {opts.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
