"""Stability stress matrix at small resolution: each cell one run through the command line; for each,
survived or stopped with the guard's named cause, volume drift, max speed and mechanical energy.
Writes docs/stability.md (table, largest stable dt factor per mode) and docs/img/stability.png (heat map).

    python tools/stress.py                   # the whole matrix (about 15 min on a 2-core CPU)
    python tools/stress.py --axis dt         # one axis

Axes: dt as a multiple of the time-step limit (isph: a fixed dt = factor x 0.25 dx / sqrt(2 g H) on a dam
break, H the column height; wcsph_biot: eq 49's coefficients cfl and force times the factor), eps0 and D50
of the ground (isph, draining column), random jitter of the initial particles, viscosity up to 1000x
water, still water for 20 s, a violent impact (dam break onto the far wall, long run), both modes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from taichi_sph.cli_process import run_case_cli

ROOT = Path(__file__).resolve().parents[1]

G = 9.81
MODES = ("isph", "wcsph_biot")
DT_FACTORS = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
#: small dam breaks of both modes: config, column width a, column height H, dx
DAM = {"isph": ("configs/dambreak.yaml", 0.1, 0.2, 0.01), "wcsph_biot": ("configs/dambreak_wcsph.yaml", 1.0, 2.0, 0.1)}
CODES = {0: "survived", 3: "bounds", 4: "non-finite", 5: "solver", 6: "domain", 2: "input", -1: "timeout"}


@dataclass
class Cell:
    axis: str
    value: str
    mode: str
    config: str
    sets: list[str] = field(default_factory=list)


def _dam(mode: str, end_T: float, *sets, dt: float = 0.0) -> tuple[str, list[str]]:
    """A small dam break of `mode` run to T = t sqrt(2 g / a) = end_T, ten frames (none shorter than dt)."""
    config, a, _, dx = DAM[mode]
    end = end_T / math.sqrt(2 * G / a)
    return config, [f"dx={dx:g}", f"end_time={end:.4g}", f"output.every={max(end / 10, dt):.4g}", *sets]


def cells(axes=None) -> list[Cell]:
    out = []
    for mode in MODES:
        _, _a, H, dx = DAM[mode]
        for f in DT_FACTORS:
            if mode == "isph":
                dt = f * 0.25 * dx / math.sqrt(2 * G * H)
                config, sets = _dam(mode, 3.0, f"dt={dt:.4g}", dt=dt)
            else:
                config, sets = _dam(mode, 3.0, f"timestep.cfl={0.25 * f:g}", f"timestep.force={0.25 * f:g}")
            out.append(Cell("dt", f"{f:g}x", mode, config, sets))
        for nu_factor in (1, 10, 100, 1000):
            config, sets = _dam(mode, 3.0, f"fluid.viscosity={1e-6 * nu_factor:.1e}")
            out.append(Cell("viscosity", f"{nu_factor}x water", mode, config, sets))
        for jit in (0.05, 0.1, 0.2):
            config, sets = _dam(mode, 3.0, f"water.0.jitter={jit}")
            out.append(Cell("jitter", f"{jit:g} dx", mode, config, sets))
        out.append(Cell("still water", "20 s", mode, "configs/hydrostatic.yaml",
                        [f"mode={mode}", "dx=0.025", "end_time=20", "output.every=2"]))
        config, sets = _dam(mode, 12.0)
        out.append(Cell("violent impact", "dam break to T = 12", mode, config, sets))
    for eps0 in (0.1, 0.2, 0.3, 0.5, 0.8, 0.95):  # 0.1: below the 2D pore-lattice floor 0.174, an input error
        out.append(Cell("eps0", f"{eps0:g}", "isph", "configs/darcy_column.yaml",
                        ["dx=0.02", f"water.0.porosity={eps0}", f"soil.regions.0.eps0={eps0}"]))
    for d50 in (1e-4, 1e-3, 1e-2, 1e-1):
        out.append(Cell("D50", f"{d50 * 1000:g} mm", "isph", "configs/darcy_column.yaml",
                        ["dx=0.02", f"soil.regions.0.d50={d50:g}"]))
    if axes:
        out = [c for c in out if c.axis in axes]
    return out


def run_cell(c: Cell, workdir: Path, timeout: float) -> dict:
    out = workdir / f"{c.axis}-{c.value}-{c.mode}.h5".replace(" ", "_")
    res = run_case_cli(c.config, out, c.sets, timeout=timeout, cwd=ROOT)
    row = {"axis": c.axis, "value": c.value, "mode": c.mode, "sets": c.sets, "rc": res.rc,
           "outcome": CODES.get(res.rc, f"exit {res.rc}"), "seconds": res.seconds,
           "message": res.message if res.rc != 0 else ""}
    if out.exists():
        try:
            row.update(measure(out))
        except Exception as exc:  # noqa: BLE001
            row["message"] += f"; run file unreadable: {exc}"
        out.unlink()
    return row


def measure(path: Path) -> dict:
    """Volume drift, max speed and the change of mechanical energy (kinetic + potential of the water)."""
    from taichi_sph.io.hdf5 import RunFile

    with RunFile(path) as rf:
        d = rf.diagnostics()
        if "time" not in d or not len(d["time"]):  # stopped inside the first step: frame 0 only
            d = {"time": np.zeros(0)}
        m = float(rf.attrs["particle_mass"])
        water = rf.kind == 0

        def potential(i):
            f = rf.frame(i)
            z = f["position"][water & f["active"]][:, -1]
            return m * G * float(np.sum(z))

        e0 = potential(0) + (float(d["kinetic_energy"][0]) if len(d["time"]) else 0.0)
        e1 = potential(rf.n_frames - 1) + (float(d["kinetic_energy"][-1]) if len(d["time"]) else 0.0)
        e_ref = potential(0) - m * G * float(rf.frame(0)["position"][water][:, -1].min()) * water.sum()
        return {"t_end": float(rf.times[-1]), "volume_drift": float(d["water_volume"][-1] / d["water_volume"][0] - 1)
                if len(d["time"]) else float("nan"), "max_speed": float(np.nanmax(d["max_speed"])) if len(d["time"])
                else float("nan"),
                # change of KE + PE relative to the initial potential energy above the lowest particle
                "energy_change": (e1 - e0) / e_ref if e_ref > 0 else float("nan"),
                "removed": int(rf.attrs.get("removed_particles", 0))}


def largest_stable_dt(rows, mode: str) -> float:
    """The largest dt factor such that it and every smaller factor survived."""
    best = 0.0
    for f in DT_FACTORS:
        r = [x for x in rows if x["axis"] == "dt" and x["mode"] == mode and x["value"] == f"{f:g}x"]
        if not r or r[0]["rc"] != 0:
            break
        best = f
    return best


def _fmt(x, spec):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def heat_map(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    labels = []
    for r in rows:
        key = f"{r['axis']}: {r['value']}"
        if key not in labels:
            labels.append(key)
    colours = {"survived": 0, "bounds": 1, "non-finite": 2, "solver": 3, "domain": 4}
    grid = np.full((len(labels), len(MODES)), np.nan)
    text = {}
    for r in rows:
        i, j = labels.index(f"{r['axis']}: {r['value']}"), MODES.index(r["mode"])
        grid[i, j] = colours.get(r["outcome"], 5)
        drift = r.get("volume_drift", float("nan"))
        text[i, j] = r["outcome"] + (f"\ndrift {100 * drift:+.2f}%" if math.isfinite(drift) else "")
    cmap = ListedColormap(["#4caf50", "#ff9800", "#e53935", "#8e24aa", "#1e88e5", "#9e9e9e"])
    fig, ax = plt.subplots(figsize=(6.5, 0.32 * len(labels) + 1.2))
    ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-0.5, vmax=5.5, aspect="auto")
    for (i, j), s in text.items():
        ax.text(j, i, s, ha="center", va="center", fontsize=6)
    ax.set_xticks(range(len(MODES)), MODES)
    ax.set_yticks(range(len(labels)), labels, fontsize=7)
    ax.set_title("stability matrix (blank: not run for that mode)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(rows, elapsed: float, machine: str, md: Path, img: Path) -> None:
    lines = ["# Stability", "",
             (f"Produced by `python tools/stress.py` on {machine}; {elapsed / 60:.1f} min in all. Each cell is one "
             "run at small resolution through the command line. Outcome: survived, or the cause family of the "
             "stability guard that stopped it (exit codes 3 bounds, 4 non-finite, 5 solver, 6 domain; see "
             "`taichi_sph/errors.py`). Volume drift and max speed come from the per-step diagnostics up to "
             "the end or the stop; energy change is (KE + PE)_end - (KE + PE)_0 over the initial potential "
             "energy above the lowest particle (a dam break dissipates, so it is negative; positive means "
             "energy was created)."), "",
             ("Time-step axis: mode isph runs a fixed dt = factor x 0.25 dx / sqrt(2 g H) on a dam break "
             "(H = 0.2 m, dx = 1 cm); mode wcsph_biot multiplies eq 49's coefficients `timestep.cfl` and "
             "`timestep.force` (0.25 each) by the factor (column 1 m x 2 m, dx = 10 cm)."), "",
             "## Largest stable time-step factor", "", "| mode | largest factor that survived (all smaller too) |",
             "|---|---|"]
    for mode in MODES:
        best = largest_stable_dt(rows, mode)
        text = f">= {best:g}x (every factor tried survived)" if best == DT_FACTORS[-1] else f"{best:g}x"
        lines.append(f"| {mode} | {text} |")
    lines += ["", ("Mode wcsph_biot's step walks the neighbours once and takes its pressures from a density predicted "
                   "along the line through the last two passes; its acoustic modes are stable up to `timestep.cfl` "
                   "0.65 (2.6x the default; the solver warns above 0.64), where the step of two passes allowed 1.85 "
                   "and survived 4x here (docs/wcsph.md, \"One step\"). 4x (cfl 1.0) is beyond that bound.")]
    lines += ["", "## Matrix", "", ("| axis | value | mode | outcome | volume drift | max speed m/s | energy change "
              "| removed | reached t s | wall s | message |"), "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['axis']} | {r['value']} | {r['mode']} | {r['outcome']} | "
                     f"{_fmt(100 * r.get('volume_drift', float('nan')), '+.3f')} % | "
                     f"{_fmt(r.get('max_speed', float('nan')), '.3g')} | "
                     f"{_fmt(r.get('energy_change', float('nan')), '+.3f')} | {r.get('removed', '')} | "
                     f"{_fmt(r.get('t_end', float('nan')), '.3g')} | {r['seconds']:.1f} | "
                     f"{r['message'].replace('|', '/')} |")
    lines += ["", "![stability matrix](img/stability.png)", ""]
    md.write_text("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--axis", action="append", help="run only these axes (repeatable)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "stability.md"))
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per cell")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the report and heat map from the JSON beside --out without running")
    args = ap.parse_args(argv)
    md = Path(args.out)
    sys.path.insert(0, str(ROOT / "tools"))
    from bench import machine

    if args.report_only:
        data = json.loads(md.with_suffix(".json").read_text())
        heat_map(data["rows"], md.parent / "img" / "stability.png")
        write_report(data["rows"], data["seconds"], data.get("machine", machine()), md, md.parent / "img" / "stability.png")
        return 0
    todo = cells(args.axis)
    if not todo:
        print("stress: no cells for these axes", file=sys.stderr)
        return 2
    (md.parent / "img").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory(prefix="stress-") as tmp:
        for c in todo:
            r = run_cell(c, Path(tmp), args.timeout)
            print(f"{c.axis:15s} {c.value:20s} {c.mode:11s} {r['outcome']:10s} {r['seconds']:6.1f} s {r['message']}",
                  flush=True)
            rows.append(r)
    elapsed = time.perf_counter() - t0
    heat_map(rows, md.parent / "img" / "stability.png")
    write_report(rows, elapsed, machine(), md, md.parent / "img" / "stability.png")
    md.with_suffix(".json").write_text(json.dumps({"seconds": elapsed, "machine": machine(), "rows": rows}, indent=1))
    print(f"wrote {md} ({elapsed / 60:.1f} min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
