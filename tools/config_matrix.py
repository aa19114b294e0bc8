"""Every shipped config on one Taichi backend: does it run, and in what wall time.

Runs each config of configs/ (each variant a user would start, and the 3D ones) with `--arch ARCH` and
nothing else changed but a shortened `end_time` where the full run is long, and tabulates per run: exit
status, the run file's own status, steps, particles, wall time of the whole process (Taichi start and
JIT included), the step loop's seconds and particle-steps per second. Two-stage cases run their stage 1
(shortened) first and start stage 2 from it.

    python tools/config_matrix.py --arch cuda [--jobs 4] [--only dambreak ...] [--out-dir DIR]
        [--report docs/performance.md]

`--jobs` runs that many processes at once (each compiles its own kernels, which is most of a short
run's time); their wall times are then those of a shared device, and the table says so. With `--report`
the table goes into that file between `<!-- configs:begin -->` and `<!-- configs:end -->`. Exits 1 when a
run fails.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- configs:begin -->", "<!-- configs:end -->"

#: (name, config, variant or None, end_time or None (the config's own), stage-1 name this one starts from)
#: isph steps are 1 ms or adaptive near it; wcsph_biot steps are 0.02-0.2 ms: end times are chosen so that
#: each run takes some hundreds of steps.
RUNS = [
    ("breakwater", "breakwater", None, 0.2, None),
    ("bubble", "bubble", None, 0.05, None),
    ("channel_startup", "channel_startup", None, 0.02, None),
    ("column_collapse", "column_collapse", None, 0.05, None),
    ("consolidation", "consolidation", None, 0.02, None),
    ("dambreak", "dambreak", None, 0.2, None),
    ("dambreak_3d", "dambreak", "3d", 0.1, None),
    ("dambreak_wcsph", "dambreak_wcsph", None, 0.2, None),
    ("dambreak_wcsph_3d", "dambreak_wcsph", "3d", 0.05, None),
    ("darcy_column", "darcy_column", None, None, None),
    ("darcy_column_3d", "darcy_column", "3d", 0.1, None),
    ("embankment_stage1", "embankment", "geostatic", 0.02, None),
    ("embankment", "embankment", None, 0.02, "embankment_stage1"),
    ("embankment_dry_stage1", "embankment", "dry_geostatic", 0.02, None),
    ("embankment_dry", "embankment", "dry", 0.02, "embankment_dry_stage1"),
    ("freefall", "freefall", None, None, None),
    ("freefall_coarse", "freefall", "coarse", 0.3, None),
    ("granular_collapse", "granular_collapse", None, 0.05, None),
    ("hydrostatic", "hydrostatic", None, 0.2, None),
    ("hydrostatic_3d", "hydrostatic", "3d", 0.1, None),
    ("infinite_slope", "infinite_slope", None, 0.05, None),
    ("levee_seepage", "levee_seepage", None, 0.05, None),
    ("permeameter", "permeameter", None, 0.2, None),
    ("porous_dambreak", "porous_dambreak", None, 0.2, None),
    ("sheetpile_stage1", "sheetpile", "geostatic", 0.02, None),
    ("sheetpile", "sheetpile", None, 0.02, "sheetpile_stage1"),
    ("soil_column", "soil_column", None, 0.05, None),
    ("stokes_plate", "stokes_plate", None, 0.02, None),
    ("taylor_green", "taylor_green", None, None, None),
    ("upward_seepage", "upward_seepage", None, 0.05, None),
    ("viscous_collapse", "viscous_collapse", None, 0.05, None),
]


def run_one(name, config, variant, end_time, stage1, arch, out_dir: Path, timeout: float) -> dict:
    out = out_dir / f"{name}.h5"
    cmd = [sys.executable, "-m", "taichi_sph.cli", "--config", str(ROOT / "configs" / f"{config}.yaml"),
           "--arch", arch, "--out", str(out), "-q"]
    if variant:
        cmd += ["--variant", variant]
    if end_time is not None:
        cmd += ["--set", f"end_time={end_time}"]
    if stage1:
        cmd += ["--set", f"wcsph.soil.start_from.run={out_dir / (stage1 + '.h5')}"]
    env = dict(os.environ, TAICHI_SPH_PROGRESS="0", TI_LOG_LEVEL="warn",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    row = {"name": name, "config": config, "variant": variant or "", "end_time": end_time}
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
        rc, text = r.returncode, (r.stderr + r.stdout)
    except subprocess.TimeoutExpired as exc:
        rc, text = 124, f"timed out after {timeout:.0f} s {exc.stderr or ''}"
    row["process_seconds"] = time.perf_counter() - t0
    row["rc"] = rc
    (out_dir / f"{name}.log").write_text(text if isinstance(text, str) else text.decode(errors="replace"))
    if rc != 0:
        lines = [ln for ln in str(text).strip().splitlines() if ln.strip()]
        row["error"] = (lines[-1] if lines else "?")[:200]
    if out.exists():
        try:
            import h5py

            with h5py.File(out, "r") as f:
                a = f.attrs
                row.update(arch_used=str(a.get("arch", "")), precision=str(a.get("precision", "")),
                           status=str(a.get("status", "")), steps=int(a.get("steps", 0)),
                           particles=int(f["particles/kind"].shape[0]) if "particles/kind" in f else None,
                           step_seconds=float(a.get("step_seconds", 0.0)),
                           mipps=float(a.get("mipps", 0.0)),
                           t_end=float(f["frames/time"][-1]) if "frames/time" in f and len(f["frames/time"]) else None)
        except Exception as exc:  # noqa: BLE001 - a half-written file is itself a finding
            row["file_error"] = str(exc)[:200]
    return row


def markdown(rows, info) -> str:
    lines = [
        (f"Device: {info['device']}. Host: {info['machine']}. `python tools/config_matrix.py {info['args']}` on "
         f"{info['date']}; {info['jobs']} run(s) at a time" + (" (wall times of a shared device: JIT and steps "
                                                                "of other runs overlap)" if info["jobs"] > 1 else "")
         + "."),
        "",
        ("| run | config | variant | end_time s | arch | precision | exit | status | particles | steps | "
         "process s | step loop s | M particle-steps/s |"),
        "|---|---|---|---:|---|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        end = "config" if r["end_time"] is None else f"{r['end_time']:g}"
        status = r.get("status", "") or r.get("error", "") or r.get("file_error", "")
        if r["rc"] != 0 and r.get("error"):
            status = f"{status}: {r['error']}" if r.get("status") else r["error"]
        status = status.replace("|", "/")
        lines.append(
            f"| {r['name']} | {r['config']} | {r['variant']} | {end} | {r.get('arch_used', '')} | "
            f"{r.get('precision', '')} | {r['rc']} | {status} | {r.get('particles') or ''} | {r.get('steps', '')} | "
            f"{r['process_seconds']:.1f} | {r.get('step_seconds', 0.0):.2f} | {r.get('mipps', 0.0):.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench import gpu_name, machine, replace_block  # tools/bench.py

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default="cuda", choices=["cpu", "cuda"])
    ap.add_argument("--jobs", type=int, default=1, help="runs at a time (default 1)")
    ap.add_argument("--only", nargs="+", help="only these runs (a stage 2 brings its stage 1)")
    ap.add_argument("--out-dir", type=Path, help="folder for run files and logs (default: a temporary one)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds allowed per run")
    ap.add_argument("--report", type=Path, help="write the table into this Markdown file between the markers")
    ap.add_argument("--json", type=Path, help="write the rows as JSON here")
    args = ap.parse_args(argv)
    runs = RUNS
    if args.only:
        wanted = set(args.only) | {r[4] for r in RUNS if r[0] in args.only and r[4]}
        runs = [r for r in RUNS if r[0] in wanted]
    out_dir = args.out_dir or Path(tempfile.mkdtemp(prefix="config_matrix_"))
    out_dir.mkdir(parents=True, exist_ok=True)
    by_name = {r[0]: r for r in runs}
    first = [r for r in runs if not r[4]]
    second = [r for r in runs if r[4]]
    rows = {}

    def go(r):
        row = run_one(*r, args.arch, out_dir, args.timeout)
        print(f"{row['name']:24s} rc={row['rc']} {row.get('status', '')} {row['process_seconds']:.1f} s "
              f"{row.get('error', '')}", flush=True)
        return row

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for row in pool.map(go, first):
            rows[row["name"]] = row
        for row in pool.map(go, second):
            rows[row["name"]] = row
    ordered = [rows[r[0]] for r in runs if r[0] in rows and r[0] in by_name]
    info = {"device": (gpu_name() or "CUDA GPU") if args.arch == "cuda" else "CPU", "machine": machine(), "jobs": args.jobs,
            "date": time.strftime("%Y-%m-%d"), "python": platform.python_version(),
            "args": " ".join(argv if argv is not None else sys.argv[1:])}
    table = markdown(ordered, info)
    print(table)
    if args.json:
        args.json.write_text(json.dumps({"info": info, "rows": ordered}, indent=2))
    if args.report:
        replace_block(args.report, BEGIN, END, table)
    return 1 if any(r["rc"] != 0 for r in ordered) else 0


if __name__ == "__main__":
    sys.exit(main())
