"""Time to solution on the 2D dam break: mode isph (its own stable step) against mode wcsph_biot and PySPH.

The case weakly compressible codes are measured on (configs/dambreak_wcsph.yaml): tank 4 m x 3 m,
water column 1 m x 2 m released from rest (`--variant still`), slip walls, simulated to `--until`
(0.5 s) at dx 1 cm (20k water particles) and 5 mm (80k). Reported per code: wall seconds per
simulated second (setup and JIT compilation excluded: the timing starts after `WARMUP` steps), the
number of steps, the smallest and largest step, and the surge front at the end (the largest x of any
water particle, as tools/bench_peer.py reads PySPH's). Each code runs in its own process with the
same number of CPU threads, one after the other in this script, so that they meet the same load.

- isph: mode isph on the same config (`--set mode=isph`), PPE `--ppe` (default mg_pcg), dt auto with
  timestep.cfl 0.2 and initial_speed sqrt(2 g H) = 6.26 m/s (the speed the front reaches), the
  setting of configs/dambreak.yaml scaled to this column: about 0.3 ms at dx 1 cm;
- wcsph_biot: eq 49's adaptive step (c0 = 10 sqrt(2 g H)), as tools/bench_wcsph.py runs it;
- PySPH dam_break_2d through tools/bench_peer.py's child, when `--pysph-python` names a Python with
  PySPH installed (docs/performance.md, "Peer comparison", says how).

    python tools/bench_time_to_solution.py [--dx 0.01 0.005] [--until 0.5] [--threads 2]
                                           [--ppe mg_pcg ell_pcg] [--pysph-python PATH] [--json FILE]
"""

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WARMUP = 5
G = 9.81
HEIGHT = 2.0

CHILD = r"""
import json, math, sys, time
sys.path.insert(0, 'tools'); sys.path.insert(0, '.')
from taichi_sph import backend
mode, ppe, dx, until, threads, warmup = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), \
    int(sys.argv[5]), int(sys.argv[6])
overrides = [f"dx={dx}", *json.loads(sys.argv[7])]
backend.init('cpu', 'f64' if mode == 'isph' else 'f32', threads=threads)
from taichi_sph.config import load_config
from taichi_sph.probes import surge_front
from taichi_sph.run import TimeStepper
from taichi_sph.scene import WATER, build_scene

if mode == 'isph':  # the same case without the wcsph section (released from rest, as variant still)
    from taichi_sph.config.load import read_yaml
    raw = read_yaml('configs/dambreak_wcsph.yaml')
    for key in ('wcsph', 'variants', 'output'):
        raw.pop(key, None)
    cfg = load_config(data=raw, overrides=overrides)
else:
    cfg = load_config('configs/dambreak_wcsph.yaml', overrides, variant='still')
scene = build_scene(cfg)
if mode == 'isph':
    from taichi_sph.isph.solver import ISPHSolver as Solver
else:
    from taichi_sph.wcsph.solver import WCSPHSolver as Solver
solver = Solver(cfg, scene)
solver.initial_diagnostics()
stepper = TimeStepper(cfg, solver.g_abs)

def step():
    if mode == 'isph':
        dt = stepper.choose(solver.last.get('max_speed', 0.0))[0]
    else:
        dt = stepper.choose(0.0, solver.propose_dt())[0]
    last = solver.step(dt)
    return dt, last

for _ in range(warmup):
    step()
t_start = solver.time
dts, iters = [], []
t0 = time.perf_counter()
while solver.time < until - 1e-12:
    dt, last = step()
    dts.append(dt)
    iters.append(last.get('cg_iterations', 0))
wall = time.perf_counter() - t0
n = solver.n
water = solver.kind.to_numpy()[:n] == WATER
x = solver.x.to_numpy()[:n][water]
active = solver.active.to_numpy()[:n][water] == 1
front = float(x[active, 0].max())
print(json.dumps({"water_particles": int(water.sum()), "steps": len(dts), "simulated": solver.time - t_start,
                  "end_time": solver.time, "wall_seconds": wall, "dt_min": min(dts), "dt_max": max(dts),
                  "front_x": front, "cg_iterations_mean": sum(iters) / len(iters) if mode == 'isph' else None}))
"""


def run_ours(mode: str, ppe: str, dx: float, until: float, threads: int) -> dict:
    overrides = []
    if mode == "isph":
        overrides = ["mode=isph", "dt=auto", "timestep.cfl=0.2",
                     f"timestep.initial_speed={math.sqrt(2 * G * HEIGHT):.3f}",
                     f"isph.ppe.type={ppe}", "isph.ppe.max_iterations=20000"]
    env = dict(os.environ, TI_CPU_MAX_NUM_THREADS=str(threads), TI_LOG_LEVEL="error")
    r = subprocess.run([sys.executable, "-c", CHILD, mode, ppe, str(dx), str(until), str(threads), str(WARMUP),
                        json.dumps(overrides)], capture_output=True, text=True, env=env, cwd=ROOT, check=False)
    lines = (r.stdout or "").strip().splitlines()
    if r.returncode != 0 or not lines:
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["?"]
        return {"error": f"exit {r.returncode}: {tail[0][:200]}"}
    return json.loads(lines[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dx", type=float, nargs="+", default=[0.01, 0.005])
    ap.add_argument("--until", type=float, default=0.5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--ppe", nargs="+", default=["mg_pcg"], choices=["mg_pcg", "ell_pcg", "sparse_cg"])
    ap.add_argument("--skip-wcsph", action="store_true")
    ap.add_argument("--pysph-python", default=None, help="a Python with PySPH installed (default: PySPH not run)")
    ap.add_argument("--json", help="also write the results to this file")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tools"))
    from bench import machine

    load0 = os.getloadavg()[0]
    rows = []
    for dx in args.dx:
        runs = [(f"isph ({p})", "isph", p) for p in args.ppe]
        if not args.skip_wcsph:
            runs.append(("wcsph_biot (f32)", "wcsph_biot", ""))
        for name, mode, ppe in runs:
            r = run_ours(mode, ppe, dx, args.until, args.threads)
            rows.append({"dx": dx, "code": name, **r, "load_after": os.getloadavg()[0]})
            print(f"done dx {dx:g} {name}: {r}", file=sys.stderr, flush=True)
        if args.pysph_python:
            from bench_peer import run_pysph

            r = run_pysph(args.pysph_python, dx, 0, args.until, args.threads)
            if "error" not in r:
                r = {**r, "simulated": r["simulated_time"], "steps": r["steps"]}
            rows.append({"dx": dx, "code": "PySPH dam_break_2d", **r, "load_after": os.getloadavg()[0]})
    print(f"2D dam break 4 m x 3 m, column 1 m x 2 m from rest, to t = {args.until:g} s; {machine()}; "
          f"{args.threads} threads; load average {load0:.1f} at start, {os.getloadavg()[0]:.1f} at end")
    print()
    print("| dx | code | water particles | steps | dt min / max (ms) | wall s | wall s per simulated s | "
          "CG iterations (mean) | front x at the end (m) | front vs wcsph_biot |")
    print("|---|---|---:|---:|---|---:|---:|---:|---:|---:|")
    ok = True
    for dx in args.dx:
        mine = [r for r in rows if r["dx"] == dx]
        ref = next((r for r in mine if r["code"].startswith("wcsph") and "error" not in r), None)
        for r in mine:
            if "error" in r:
                ok = False
                print(f"| {dx:g} | {r['code']} | not run: {r['error']} | | | | | | | |")
                continue
            per = r["wall_seconds"] / r["simulated"]
            rel = f"{100 * (r['front_x'] / ref['front_x'] - 1):+.2f} %" if ref else ""
            it = f"{r['cg_iterations_mean']:.1f}" if r.get("cg_iterations_mean") else ""
            print(f"| {dx:g} | {r['code']} | {r['water_particles']} | {r['steps']} | {1e3 * r['dt_min']:.4f} / "
                  f"{1e3 * r['dt_max']:.4f} | {r['wall_seconds']:.1f} | {per:.1f} | {it} | {r['front_x']:.3f} "
                  f"| {rel} |")
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine(), "threads": args.threads, "load_average": load0,
                                               "until": args.until, "rows": rows}, indent=2))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
