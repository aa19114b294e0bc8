"""Throughput benchmark of mode wcsph_biot: particle-steps per second on the 2D dam break.

Runs configs/dambreak_wcsph.yaml (tank 4 m x 3 m, column 1 m x 2 m) at the requested spacings in one
process, lets the collapse start (warm-up, JIT compilation excluded and reported separately), then
times a fixed number of steps with the time step of eq 49 and reports particle-steps per second
(fluid particles x steps / wall seconds), the split between phases and how often neighbour lists
were rebuilt. The steps are timed in ten chunks; besides the mean, the rate of the fastest chunk is reported (other
processes on a shared machine slow some chunks down). Writes docs/performance_wcsph.json and the table
in docs/performance_wcsph.md.

    python tools/bench_wcsph.py [--dx 0.01 0.005] [--steps 300] [--warmup 200] [--precision f32 f64]
    python tools/bench_wcsph.py --against /path/to/other/checkout --rounds 3 [...]

Each precision runs in its own process (one Taichi runtime per process); the table holds them all.
CPU seconds per wall second of the timed step loop (time.process_time against time.perf_counter; 2 =
both cores of a 2-thread run busy) shows the serial parts and the interference of other processes.
With --against, the same cases also run with the code of another checkout (this tool, with the
`taichi_sph` package and configs of that checkout), alternating with this one `--rounds` times, so that
both see the same machine load; the table then gains the per-round rates and their ratio, with the load
average (os.getloadavg, 1 minute) at the start and end of each run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CODE = ROOT  # the checkout whose package and configs are measured (--code)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench import machine


def bench_case(dx: float, steps: int, warmup: int, overrides=(), until: float | None = None) -> dict:
    """Time `steps` steps after `warmup` ones; with `until`, time every step from the warm-up on up to that
    simulated time instead (stability over a whole run: smallest and largest step, the surge front, i.e.
    the largest x of any water particle, at the end)."""
    from taichi_sph.config import load_config
    from taichi_sph.run import TimeStepper
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    cfg = load_config(CODE / "configs" / "dambreak_wcsph.yaml", [f"dx={dx}", *overrides])
    scene = build_scene(cfg)
    t0 = time.perf_counter()
    solver = make_solver(cfg, scene)
    solver.initial_diagnostics()
    stepper = TimeStepper(cfg, solver.g_abs)
    for _ in range(warmup):
        solver.step(stepper.choose(0.0, solver.propose_dt())[0])
    setup = time.perf_counter() - t0
    for k in solver.timers:
        solver.timers[k] = 0.0
    rebuilds0 = solver.rebuilds
    chunk = max(1, steps // 10)
    chunks = []
    dts = []
    cpu0 = time.process_time()
    main0 = time.thread_time()
    if until is not None:
        chunk = 100
        while solver.time < until:
            t0 = time.perf_counter()
            for _ in range(chunk):
                dt = stepper.choose(0.0, solver.propose_dt())[0]
                dts.append(dt)
                solver.step(dt)
                if solver.time >= until:
                    break
            chunks.append(time.perf_counter() - t0)
    else:
        for _ in range(0, steps, chunk):
            t0 = time.perf_counter()
            for _ in range(chunk):
                solver.step(stepper.choose(0.0, solver.propose_dt())[0])
            chunks.append(time.perf_counter() - t0)
    cpu = time.process_time() - cpu0
    main = time.thread_time() - main0
    steps = len(dts) if until is not None else chunk * len(chunks)
    run_extra = {}
    if until is not None:
        from taichi_sph.scene import WATER

        n = solver.n
        water = solver.kind.to_numpy()[:n] == WATER
        run_extra = {"dt_min": min(dts), "dt_max": max(dts), "front_x": float(solver.x.to_numpy()[:n][water, 0].max()),
                     "tank_length": float(solver.cfg.tank.size[0])}
    wall = sum(chunks)
    best = min(chunks[:-1] or chunks) / chunk  # the last chunk of a run to `until` may be short
    return {
        "case": "dam break 2D", "dx": dx, "fluid_particles": solver.n_fluid, "all_particles": solver.n,
        "steps": steps, "simulated_time_at_end": solver.time, "seconds_per_step": wall / steps,
        "particle_steps_per_second": solver.n_fluid * steps / wall, "mipps": solver.n_fluid * steps / wall / 1e6,
        "mipps_best_chunk": solver.n_fluid / best / 1e6,
        "cpu_over_wall": cpu / wall,
        "cpu_seconds_per_step": cpu / steps,
        # CPU time of the calling thread: Python, kernel launches, host reads and the serial parts of
        # kernels; Taichi's worker threads run the parallel loops
        "main_thread_cpu_seconds_per_step": main / steps,
        "steps_per_rebuild": steps / max(solver.rebuilds - rebuilds0, 1),
        "phase_seconds_per_step": {k: v / steps for k, v in solver.timers.items()},
        "setup_and_warmup_seconds": setup,
        **run_extra,
    }


def load_average() -> float:
    """1-minute load average of the machine (processes running or waiting for a core)."""
    return os.getloadavg()[0]


def markdown(results, info) -> str:
    phases = list(results[0]["phase_seconds_per_step"])
    lines = [
        "# Performance of mode wcsph_biot",
        "",
        (f"Machine: {info['machine']}; Taichi {info['taichi']}, arch {info['arch']}, {info['threads']} threads. "
         f"Produced by `python tools/bench_wcsph.py` on {info['date']}."),
        "",
        "2D dam break (configs/dambreak_wcsph.yaml: tank 4 m x 3 m, column 1 m x 2 m, slip walls), timed after",
        f"{info['warmup']} steps of the collapse, adaptive step of eq 49. Particle-steps per second count fluid",
        "particles. Times per step in milliseconds; JIT compilation excluded. The steps are timed in ten chunks;",
        "the fastest chunk is the rate with the least interference from other processes, and CPU seconds per",
        "wall second (2 = both cores busy with this run) shows how much of the machine the run had (the",
        "machine is shared; the 20k runs, with ~2 ms loops, suffer most). Load: the 1-minute load average at",
        "the start / end of the run (other processes on the machine). CPU ms per step counts all",
        "threads; the main thread's share is the serial part of the step loop (Python, kernel launches,",
        "reads of the reductions, serial parts of kernels), while Taichi's worker threads run the parallel",
        "loops.",
        "",
        "| precision | dx | fluid particles | all particles | M particle-steps/s (mean) | (fastest chunk) | "
        "CPU s / wall s | CPU ms/step | main thread CPU ms/step | load | ms/step | steps per list rebuild | "
        + " | ".join(phases) + " | setup+warm-up s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(phases) + "---|",
    ]
    for r in results:
        ph = " | ".join(f"{1e3 * r['phase_seconds_per_step'][p]:.2f}" for p in phases)
        lines.append(f"| {r['precision']} | {r['dx']:g} | {r['fluid_particles']} | {r['all_particles']} | {r['mipps']:.2f} | "
                     f"{r['mipps_best_chunk']:.2f} | {r['cpu_over_wall']:.2f} | "
                     f"{1e3 * cpu_per_step(r):.2f} | "
                     f"{1e3 * r.get('main_thread_cpu_seconds_per_step', float('nan')):.2f} | "
                     f"{r['load_start_end'][0]:.1f} / {r['load_start_end'][1]:.1f} | "
                     f"{1e3 * r['seconds_per_step']:.2f} | {r['steps_per_rebuild']:.1f} | {ph} | "
                     f"{r['setup_and_warmup_seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def run_one(args) -> list:
    """All spacings at one precision, in this process."""
    global CODE
    if args.code:  # the package of another checkout
        CODE = Path(args.code).resolve()
        sys.path.insert(0, str(CODE))
    from taichi_sph import backend

    be = backend.init(args.arch, args.precision[0])
    results = []
    for dx in args.dx:
        load0 = load_average()
        r = bench_case(dx, args.steps, args.warmup, args.overrides)
        r["precision"] = be["precision"]
        r["load_start_end"] = [load0, load_average()]
        print(f"{be['precision']}, dx {dx:g}: {r['fluid_particles']} fluid particles, {r['mipps']:.2f} M particle-steps/s "
              f"(fastest chunk {r['mipps_best_chunk']:.2f}, cpu/wall {r['cpu_over_wall']:.2f}), "
              f"{1e3 * r['seconds_per_step']:.2f} ms/step, {r['steps_per_rebuild']:.1f} steps per rebuild, "
              f"phases {', '.join(f'{k} {1e3 * v:.2f}' for k, v in r['phase_seconds_per_step'].items())} ms",
              flush=True)
        results.append(r)
    return results


def child(tree: Path, prec: str, args, path: Path) -> list:
    """One precision, all spacings, in a process of its own with the code of checkout `tree`."""
    cmd = [sys.executable, __file__, "--precision", prec, "--results-json", str(path), "--code", str(tree),
           "--arch", args.arch, "--steps", str(args.steps), "--warmup", str(args.warmup),
           "--dx", *map(str, args.dx)]
    for o in args.overrides:
        cmd += ["--set", o]
    subprocess.run(cmd, check=True, env=dict(os.environ, PYTHONPATH=str(tree)))
    return json.loads(path.read_text())


def cpu_per_step(r: dict) -> float:
    """CPU seconds per step of the timed loop (all threads; less sensitive to other processes than the
    wall time: a thread waiting for a core costs no CPU time)."""
    return r["cpu_over_wall"] * r["seconds_per_step"]


def describe_checkout(path: str) -> str:
    """`commit <sha>` of a git checkout (its folder name when git cannot tell), for the tables."""
    try:
        sha = subprocess.run(["git", "-C", str(path), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        return f"commit {sha}"
    except (OSError, subprocess.CalledProcessError):
        return Path(path).name


def comparison_markdown(rounds, against: str) -> str:
    """Rounds of (this checkout, the other) run back to back: rates, CPU time per step and their ratios."""
    lines = ["", f"Interleaved with the code of {against} (the other checkout), round by round:",
             "M particle-steps/s (mean over the timed steps), CPU s / wall s, CPU ms per step (all threads),",
             "the 1-minute load average at start / end of each run, and the ratios this / other of the rate",
             "and other / this of the CPU time.",
             "Main: the main thread's CPU ms per step (the serial part).",
             "", "| precision | dx | round | this: M p-steps/s | CPU/wall | CPU ms/step | main | load | "
             "other: M p-steps/s | CPU/wall | CPU ms/step | main | load | rate ratio | CPU ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    ratios = {}
    for k, (new, old) in enumerate(rounds):
        for a, b in zip(new, old):
            ratio, cratio = a["mipps"] / b["mipps"], cpu_per_step(b) / cpu_per_step(a)
            ratios.setdefault((a["precision"], a["dx"]), []).append((ratio, cratio))
            la, lb = a["load_start_end"], b["load_start_end"]
            ma, mb = (1e3 * r.get("main_thread_cpu_seconds_per_step", float("nan")) for r in (a, b))
            lines.append(f"| {a['precision']} | {a['dx']:g} | {k + 1} | {a['mipps']:.2f} | "
                         f"{a['cpu_over_wall']:.2f} | {1e3 * cpu_per_step(a):.2f} | {ma:.2f} | "
                         f"{la[0]:.1f} / {la[1]:.1f} | {b['mipps']:.2f} | {b['cpu_over_wall']:.2f} | "
                         f"{1e3 * cpu_per_step(b):.2f} | {mb:.2f} | {lb[0]:.1f} / {lb[1]:.1f} | "
                         f"{ratio:.2f} | {cratio:.2f} |")
    for (prec, dx), r in ratios.items():
        med = [sorted(x)[len(x) // 2] for x in zip(*r)]
        lines.append(f"| {prec} | {dx:g} | median | | | | | | | | | | | {med[0]:.2f} | {med[1]:.2f} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dx", type=float, nargs="+", default=[0.01, 0.005])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--precision", nargs="+", default=["f32", "f64"], choices=["auto", "f32", "f64"])
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance_wcsph.md"))
    ap.add_argument("--results-json", help=argparse.SUPPRESS)
    ap.add_argument("--against", help="another checkout to compare with, run alternately with this one")
    ap.add_argument("--rounds", type=int, default=3, help="alternations with --against")
    ap.add_argument("--code", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.results_json:  # a child process: one precision
        Path(args.results_json).write_text(json.dumps(run_one(args)))
        return
    results = []
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        if args.against:
            for k in range(args.rounds):
                new, old = [], []
                for prec in args.precision:
                    new += child(ROOT, prec, args, Path(tmp) / f"n{k}{prec}.json")
                    old += child(Path(args.against).resolve(), prec, args, Path(tmp) / f"o{k}{prec}.json")
                rounds.append((new, old))
            results = rounds[-1][0]
        else:
            for prec in args.precision:
                results += child(ROOT, prec, args, Path(tmp) / f"{prec}.json")
    import taichi as ti

    info = {"machine": machine(), "taichi": ".".join(map(str, ti.__version__)), "arch": args.arch,
            "threads": os.environ.get("TI_CPU_MAX_NUM_THREADS", os.cpu_count()),
            "date": time.strftime("%Y-%m-%d"), "warmup": args.warmup, "overrides": args.overrides}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    info["against"] = describe_checkout(args.against) if args.against else None
    payload = {"info": info, "results": results, "rounds": rounds}
    out.with_suffix(".json").write_text(json.dumps(payload, indent=2))
    text = markdown(results, info)
    if rounds:
        text += comparison_markdown(rounds, info["against"])
    out.write_text(text)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
