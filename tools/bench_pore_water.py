"""Cost of the pore water's stiffness in mode wcsph_biot: steps and wall time per simulated second against
the ratio K_f / M of the water's EOS modulus K_f = rho_w c0^2 to the soil's constrained modulus M
(docs/biot.md, "Storage and c_v").

For each case and each ratio the water's sound speed is set to sqrt(ratio M / rho_w) (M from the config,
`Config.soil_modulus`), or kept at the config's own value for the ratio `config`; the run starts from the
config's start, takes `--warmup` steps (compilation excluded), then steps for `--time` simulated seconds.
Every run is a process of its own, and the ratios are run in turn, `--repeat` rounds, so that a loaded
machine slows each of them alike; the ratio of times is taken within a round. CPU seconds (one thread:
TI_CPU_MAX_NUM_THREADS=1) are less disturbed by other processes than wall seconds.

    python tools/bench_pore_water.py [--ratios config 20 40] [--time 0.01] [--repeat 2]

Cases: configs/consolidation.yaml (Terzaghi column) and configs/embankment.yaml's `geostatic` variant (the
levee at rest with its river and pore water; the config pins c0 = 17.2 m/s).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASES = {
    "consolidation": ("configs/consolidation.yaml", []),
    "levee": ("configs/embankment.yaml", ["--variant", "geostatic"]),
}


def one(case: str, ratio: str, sim_time: float, warmup: int) -> dict:
    from taichi_sph import backend
    from taichi_sph.config import load_config
    from taichi_sph.run import TimeStepper
    from taichi_sph.scene import build_scene
    from taichi_sph.wcsph.solver import WCSPHSolver

    backend.init("cpu", "auto")
    path, extra = CASES[case]
    variant = extra[1] if extra else None
    cfg = load_config(ROOT / path, [], variant=variant)
    m = cfg.soil_modulus()
    sets = []
    if ratio != "config":
        sets = [f"wcsph.water.sound_speed={(float(ratio) * m / cfg.fluid.density) ** 0.5!r}"]
        cfg = load_config(ROOT / path, sets, variant=variant)
    scene = build_scene(cfg)
    solver = WCSPHSolver(cfg, scene)
    solver.initial_diagnostics()
    stepper = TimeStepper(cfg, solver.g_abs)
    for _ in range(warmup):
        solver.step(stepper.choose(0.0, solver.propose_dt())[0])
    t_start, steps = solver.time, 0
    t0, cpu0 = time.perf_counter(), time.process_time()
    while solver.time < t_start + sim_time:
        solver.step(stepper.choose(0.0, solver.propose_dt())[0])
        steps += 1
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    sim = solver.time - t_start
    c0 = solver.c_w
    return {"case": case, "ratio": ratio, "kf_over_m": cfg.fluid.density * c0**2 / m, "c0": c0, "M": m,
            "particles": solver.n, "steps_per_s": steps / sim, "wall_per_s": wall / sim, "cpu_per_s": cpu / sim,
            "steps": steps}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--ratios", nargs="+", default=["config", "20", "40"])
    ap.add_argument("--time", type=float, default=0.01, help="simulated seconds timed per run")
    ap.add_argument("--warmup", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(one(args.child[0], args.child[1], args.time, args.warmup)))
        return
    rows = []
    for case in args.cases:
        for rnd in range(args.repeat):
            for ratio in args.ratios:
                out = subprocess.run([sys.executable, __file__, "--child", case, ratio, "--time", str(args.time),
                                      "--warmup", str(args.warmup)], cwd=ROOT, capture_output=True, text=True,
                                     check=True).stdout
                r = json.loads(out.strip().splitlines()[-1])
                r["round"] = rnd
                rows.append(r)
                print(f"{case} round {rnd}: ratio {ratio} (K_f/M {r['kf_over_m']:.3g}, c0 {r['c0']:.1f} m/s, "
                      f"{r['particles']} particles): {r['steps_per_s']:.0f} steps, {r['wall_per_s']:.1f} s wall, "
                      f"{r['cpu_per_s']:.1f} s CPU "
                      f"per simulated s", flush=True)
        base = args.ratios[0]
        for rnd in range(args.repeat):
            b = next(r for r in rows if r["case"] == case and r["round"] == rnd and r["ratio"] == base)
            for r in rows:
                if r["case"] == case and r["round"] == rnd and r["ratio"] != base:
                    print(f"{case} round {rnd}: {r['ratio']} / {base}: "
                          f"steps x{r['steps_per_s'] / b['steps_per_s']:.2f}, "
                          f"wall x{r['wall_per_s'] / b['wall_per_s']:.2f}, CPU x{r['cpu_per_s'] / b['cpu_per_s']:.2f}")


if __name__ == "__main__":
    main()
