"""Before/after check for a refactor: run one short case per shipped config with one thread, then compare
two such sets frame by frame (positions, velocities, pressures). A refactor that keeps behaviour gives
zero, or round-off where the order of floating-point sums changed.

    python tools/behaviour_check.py run --src CHECKOUT_BEFORE --out /tmp/before
    python tools/behaviour_check.py run --src . --out /tmp/after
    python tools/behaviour_check.py compare /tmp/before /tmp/after

`run` imports the package from `--src` (so a git worktree of the commit before serves as the baseline)
and writes RUN.h5 and RUN.log per case into `--out`. `compare` prints one row per case and exits 1 when a
case differs by more than `--tol` (default 0: bit-identical) or is missing from either set.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: (run name, config, extra CLI arguments): every shipped config once, short enough that the set runs in
#: a few minutes on one thread; isph steps are ~1 ms, wcsph_biot steps ~0.05-0.2 ms. Configs whose default
#: needs an earlier stage's run file use the stage that makes it.
CASES = [
    ("breakwater", "breakwater", ["--set", "end_time=0.02"]),
    ("bubble", "bubble", ["--set", "end_time=0.003"]),
    ("channel_startup", "channel_startup", ["--set", "end_time=0.02"]),
    ("column_collapse", "column_collapse", ["--set", "end_time=0.003"]),
    ("consolidation", "consolidation", ["--set", "end_time=0.003"]),
    ("dambreak", "dambreak", ["--set", "end_time=0.02"]),
    ("dambreak_wcsph", "dambreak_wcsph", ["--set", "end_time=0.003"]),
    ("darcy_column", "darcy_column", ["--set", "end_time=0.02"]),
    ("embankment_geostatic", "embankment", ["--variant", "geostatic", "--set", "end_time=0.003"]),
    ("embankment_dry", "embankment", ["--variant", "dry_geostatic", "--set", "end_time=0.003"]),
    ("freefall_coarse", "freefall", ["--variant", "coarse", "--set", "end_time=0.01"]),
    ("granular_collapse", "granular_collapse", ["--set", "end_time=0.003"]),
    ("hydrostatic", "hydrostatic", ["--set", "end_time=0.02"]),
    ("infinite_slope", "infinite_slope", ["--set", "end_time=0.003"]),
    ("levee_seepage", "levee_seepage", ["--set", "end_time=0.003"]),
    ("permeameter", "permeameter", ["--set", "end_time=0.02"]),
    ("porous_dambreak", "porous_dambreak", ["--set", "end_time=0.02"]),
    ("sheetpile", "sheetpile", ["--variant", "geostatic", "--set", "end_time=0.003"]),
    ("soil_column", "soil_column", ["--set", "end_time=0.003"]),
    ("stokes_plate", "stokes_plate", ["--set", "end_time=0.02"]),
    ("taylor_green", "taylor_green", ["--set", "end_time=0.02", "--set", "dt=0.001"]),  # frames every 1 ms
    ("upward_seepage", "upward_seepage", ["--set", "end_time=0.003"]),
    ("viscous_collapse", "viscous_collapse", ["--set", "end_time=0.003"]),
]

FIELDS = ("position", "velocity", "pressure")


def run_cases(src: Path, out: Path, only: list[str] | None, sets: list[str] | None = None) -> int:
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(src), TI_CPU_MAX_NUM_THREADS="1", TAICHI_SPH_PROGRESS="0",
               TI_LOG_LEVEL="warn")
    failed = 0
    for name, config, extra in CASES:
        if only and name not in only:
            continue
        cmd = [sys.executable, "-m", "taichi_sph.cli", "--config", str(src / "configs" / f"{config}.yaml"),
               *extra, *[a for kv in sets or () for a in ("--set", kv)], "--set", "threads=1",
               "--set", "output.every=0.001", "--out", str(out / f"{name}.h5"), "-q"]
        with open(out / f"{name}.log", "w") as log:
            rc = subprocess.call(cmd, cwd=src, env=env, stdout=log, stderr=subprocess.STDOUT)
        print(f"{name:22s} rc={rc}", flush=True)
        failed += rc != 0
    return 1 if failed else 0


def compare(a_dir: Path, b_dir: Path, tol: float) -> int:
    from taichi_sph.io.hdf5 import RunFile

    bad = 0
    for name, _, _ in CASES:
        pa, pb = a_dir / f"{name}.h5", b_dir / f"{name}.h5"
        if not (pa.exists() and pb.exists()):
            print(f"{name:22s} missing in {'the first' if not pa.exists() else 'the second'} set")
            bad += 1
            continue
        with RunFile(str(pa)) as a, RunFile(str(pb)) as b:
            if a.n_frames != b.n_frames:
                print(f"{name:22s} frames differ: {a.n_frames} against {b.n_frames}")
                bad += 1
                continue
            worst = dict.fromkeys(FIELDS, 0.0)
            for i in range(a.n_frames):
                fa, fb = a.frame(i), b.frame(i)
                for k in FIELDS:
                    d = np.abs(np.asarray(fa[k], float) - np.asarray(fb[k], float))
                    worst[k] = max(worst[k], float(d.max()) if d.size else 0.0)
            steps = int(a.attrs["steps"]), int(b.attrs["steps"])
            frames = a.n_frames
        flag = "" if max(worst.values()) <= tol and steps[0] == steps[1] else "  DIFFERS"
        bad += bool(flag)
        print(f"{name:22s} frames {frames:3d} steps {steps[0]}/{steps[1]} max|diff| "
              + " ".join(f"{k} {v:.3g}" for k, v in worst.items()) + flag)
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the short cases from one checkout")
    r.add_argument("--src", type=Path, default=Path("."), help="checkout whose package and configs run")
    r.add_argument("--out", type=Path, required=True, help="folder for the run files")
    r.add_argument("--case", action="append", help="only this case (repeatable)")
    r.add_argument("--set", dest="sets", action="append", metavar="KEY=VALUE",
                   help="config override for every case, e.g. precision=f64 (repeatable)")
    c = sub.add_parser("compare", help="compare two folders of run files")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    c.add_argument("--tol", type=float, default=0.0, help="largest difference accepted (default 0)")
    args = ap.parse_args()
    if args.cmd == "run":
        return run_cases(args.src.resolve(), args.out.resolve(), args.case, args.sets)
    return compare(args.a, args.b, args.tol)


if __name__ == "__main__":
    sys.exit(main())
