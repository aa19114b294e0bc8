"""Peer comparison: PySPH's 2D dam break against ours, same geometry and particle count, same run.

PySPH (its example `dam_break_2d`: tank 4 x 3 m, water column 1 x 2 m, WCSPH, OpenMP) and
mode wcsph_biot on configs/dambreak_wcsph.yaml (the same tank and column) run one after the other
from this script at the same spacing (dx 0.01 m: 20k water particles), each for the same number of
steps from the release of the column, with the CPU threads of the machine. Setup and compilation
are excluded on both sides (PySPH compiles in `setup()`, which is not timed; both take 5 warm-up
steps first). Reported: water particles, steps, wall seconds, particle-steps per second
(water particles x steps / wall seconds) and our rate over PySPH's.

    python tools/bench_peer.py [--dx 0.01] [--steps 200] [--pysph-python PATH]

`--pysph-python` names the Python that has PySPH installed (default: this one). When PySPH cannot
be imported there, the error is printed and the script exits 1.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PYSPH_CHILD = r"""
import json, sys, time
from pysph.examples.dam_break_2d import DamBreak2D

dx, steps, out, outdir = float(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
WARMUP = 5
app = DamBreak2D(output_dir=outdir)
app.setup(["--openmp", "--dx", str(dx), "--max-steps", str(steps), "--tf", "100", "--disable-output",
           "--pfreq", "100000000", "-q"])
fluid = [pa for pa in app.particles if pa.name == "fluid"][0]
app.solver.set_max_steps(WARMUP)  # first steps: neighbour structures built, caches filled
app.solver.solve(False)
app.solver.set_max_steps(WARMUP + steps)
t0 = time.perf_counter()
app.solver.solve(False)
wall = time.perf_counter() - t0
json.dump({"water_particles": int(fluid.get_number_of_particles()), "steps": int(app.solver.count) - WARMUP,
           "wall_seconds": wall, "simulated_time": float(app.solver.t)}, open(out, "w"))
"""


def run_pysph(python: str, dx: float, steps: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "pysph_dam_break.py"
        script.write_text(PYSPH_CHILD)
        out = Path(tmp) / "pysph.json"
        env = dict(os.environ, OMP_NUM_THREADS=str(os.cpu_count()))
        r = subprocess.run([python, str(script), str(dx), str(steps), str(out), str(Path(tmp) / "out")],
                           capture_output=True, text=True, env=env, check=False)
        if r.returncode != 0 or not out.exists():
            lines = (r.stderr + r.stdout).strip().splitlines()
            errors = [line for line in lines if "Error" in line] or lines or [""]
            return {"error": f"exit {r.returncode}: {errors[-1]}"}
        return json.loads(out.read_text())


def run_ours(dx: float, steps: int, precision: str) -> dict:
    code = (
        "import json, sys; sys.path.insert(0, 'tools'); sys.path.insert(0, '.');"
        "from taichi_sph import backend; backend.init('cpu', sys.argv[3]);"
        "from bench_wcsph import bench_case;"
        "r = bench_case(float(sys.argv[1]), int(sys.argv[2]), 5);"
        "print(json.dumps({'water_particles': r['fluid_particles'], 'steps': r['steps'],"
        " 'wall_seconds': r['seconds_per_step'] * r['steps'], 'simulated_time': r['simulated_time_at_end']}))"
    )
    r = subprocess.run([sys.executable, "-c", code, str(dx), str(steps), precision], cwd=ROOT,
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        return {"error": (r.stderr.strip().splitlines() or ["?"])[-1]}
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dx", type=float, default=0.01)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--pysph-steps", type=int, default=None,
                    help="steps for PySPH (default: --steps); its dam break at dx 0.01 crashed past ~20 steps here")
    ap.add_argument("--precision", default="f32", choices=["f32", "f64"], help="ours (PySPH runs f64)")
    ap.add_argument("--pysph-python", default=sys.executable)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tools"))
    from bench import machine

    results = {"pysph": run_pysph(args.pysph_python, args.dx, args.pysph_steps or args.steps),
               f"taichi-sph ({args.precision})": run_ours(args.dx, args.steps, args.precision)}
    print(f"2D dam break, dx {args.dx:g}; {machine()}, {os.cpu_count()} threads, "
          f"load average {os.getloadavg()[0]:.1f}")
    print()
    print("| code | water particles | steps | simulated s | wall s | M particle-steps/s |")
    print("|---|---:|---:|---:|---:|---:|")
    rates = {}
    for name, r in results.items():
        if "error" in r:
            print(f"| {name} | not run: {r['error']} | | | | |")
            continue
        rates[name] = r["water_particles"] * r["steps"] / r["wall_seconds"]
        print(f"| {name} | {r['water_particles']} | {r['steps']} | {r['simulated_time']:.4f} | "
              f"{r['wall_seconds']:.2f} | {rates[name] / 1e6:.2f} |")
    if len(rates) == 2:
        ours, theirs = rates[f"taichi-sph ({args.precision})"], rates["pysph"]
        print(f"\nours / PySPH: {ours / theirs:.2f}")
        return 0
    return 1


if __name__ == "__main__":
    sys.exit(main())
