"""Throughput benchmark: particle-steps per second and time per phase for mode isph.

Runs the hydrostatic tank (2D and 3D, two sizes each) in one process, times a fixed number of steps
after a warm-up (JIT compilation excluded, reported separately), and writes docs/performance.json
and the table in docs/performance.md with the machine named.

    python tools/bench.py [--steps 20] [--arch cpu] [--out docs/performance.md]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CASES = [
    # name, dim, dx, tank size, water box max
    ("hydrostatic 2D", 2, 0.01, [0.40, 0.40], [0.40, 0.30]),
    ("hydrostatic 2D", 2, 0.0025, [0.40, 0.40], [0.40, 0.30]),
    ("hydrostatic 3D", 3, 0.02, [0.40, 0.20, 0.40], [0.40, 0.20, 0.30]),
    ("hydrostatic 3D", 3, 0.01, [0.40, 0.20, 0.40], [0.40, 0.20, 0.30]),
]


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"


def bench_case(name, dim, dx, size, wmax, steps, warmup):
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    cfg = load_config(data={"mode": "isph", "dim": dim, "dx": dx, "end_time": 1.0, "dt": 0.001,
                            "tank": {"size": size}, "water": [{"min": [0.0] * dim, "max": wmax}]})
    scene = build_scene(cfg)
    t0 = time.perf_counter()
    solver = ISPHSolver(cfg, scene)
    for _ in range(warmup):
        solver.step(0.001)
    first = time.perf_counter() - t0
    for k in solver.timers:
        solver.timers[k] = 0.0
    iters = []
    t0 = time.perf_counter()
    for _ in range(steps):
        iters.append(solver.step(0.001)["cg_iterations"])
    wall = time.perf_counter() - t0
    phases = {k: v / steps for k, v in solver.timers.items()}
    return {
        "case": name, "dim": dim, "dx": dx, "water_particles": solver.n_water, "all_particles": solver.n,
        "steps": steps, "seconds_per_step": wall / steps,
        "particle_steps_per_second": solver.n_water * steps / wall,
        "mipps": solver.n_water * steps / wall / 1e6,
        "cg_iterations_mean": sum(iters) / len(iters),
        "phase_seconds_per_step": phases,
        "setup_and_warmup_seconds": first,
    }


def markdown(results, info) -> str:
    phases = ["neighbours", "density", "predictor", "ppe_assembly", "ppe_solve", "corrector", "diagnostics"]
    lines = [
        "# Performance",
        "",
        f"Machine: {info['machine']}; Taichi {info['taichi']}, arch {info['arch']}, {info['precision']}, "
        f"{info['threads']} threads. Produced by `python tools/bench.py` on {info['date']}.",
        "",
        "Mode isph, hydrostatic tank at rest, fixed dt = 1 ms, PPE by SparseMatrixBuilder + SparseCG to a",
        "relative residual of 1e-8, warm-started from the last pressure. Particle-steps per second count",
        "water particles. Times per step in milliseconds; JIT compilation excluded (first column of setup).",
        "",
        "| case | water particles | M particle-steps/s | ms/step | CG iters | "
        + " | ".join(phases) + " | setup+warm-up s |",
        "|---|---|---|---|---|" + "---|" * len(phases) + "---|",
    ]
    for r in results:
        ph = " | ".join(f"{1e3 * r['phase_seconds_per_step'][p]:.1f}" for p in phases)
        lines.append(f"| {r['case']}, dx {r['dx']:g} | {r['water_particles']} | {r['mipps']:.3f} | "
                     f"{1e3 * r['seconds_per_step']:.1f} | {r['cg_iterations_mean']:.0f} | {ph} | "
                     f"{r['setup_and_warmup_seconds']:.1f} |")
    lines += ["", "Phase shares of the step time, largest case of each dimension:", ""]
    for dim in (2, 3):
        rs = [r for r in results if r["dim"] == dim]
        if not rs:
            continue
        r = max(rs, key=lambda r: r["water_particles"])
        tot = sum(r["phase_seconds_per_step"].values())
        share = ", ".join(f"{p} {100 * r['phase_seconds_per_step'][p] / tot:.0f} %" for p in phases)
        lines.append(f"- {dim}D, {r['water_particles']} particles: {share}.")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance.md"))
    args = ap.parse_args()
    from taichi_sph import backend

    be = backend.init(args.arch, "auto")
    import taichi as ti

    results = []
    for case in CASES:
        r = bench_case(*case, steps=args.steps, warmup=args.warmup)
        print(f"{r['case']}, dx {r['dx']:g}: {r['water_particles']} particles, {r['mipps']:.3f} M particle-steps/s, "
              f"{1e3 * r['seconds_per_step']:.1f} ms/step, CG {r['cg_iterations_mean']:.0f}", flush=True)
        results.append(r)
    info = {"machine": machine(), "taichi": ".".join(map(str, ti.__version__)), "arch": be["arch"],
            "precision": be["precision"], "threads": os.environ.get("TI_CPU_MAX_NUM_THREADS", os.cpu_count()),
            "date": time.strftime("%Y-%m-%d")}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"info": info, "results": results}, indent=2))
    out.write_text(markdown(results, info))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
