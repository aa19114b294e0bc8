"""How busy the step loop of mode wcsph_biot can keep the CPU's threads: the full step against its own
kernels launched without the host's work, round by round in one process.

For one case (default the 2D dam break at dx 1 cm, 20k water particles; `--config`, `--set`), after a
warm-up of full steps, each round times, one after the other:

- `full step`: what tools/bench_wcsph.py times (eq 49's step chosen on the host, the kick-drift kernel,
  the list-rebuild test, the pair kernel, the reductions read back);
- `full step and the guard`: the full step, and every `guard.every` steps the stability guard's field
  check as a run makes it (taichi_sph/guard.py: the packed fields gathered by one kernel, then the
  host's tests), its cost spread over the steps;
- `two kernels, no host work`: the kick-drift and the pair kernel launched back to back with the last
  step's dt and weights, no rebuild test, no reads;
- `pair kernel alone` and `kick-drift alone`;
- `empty parallel loop`: a kernel with one parallel loop over as many particles that does one add each,
  the price of a launch and of waking the threads with next to no work.

Each round starts every variant from the state saved after the warm-up (restored untimed). The full
step then runs on as a run does; the kernels alone are restored every `--chunk` calls (default 10,
fewer steps than the lists' skin lasts in the dam break), so that they never run on stale neighbour
lists.
Each line gives wall ms per step (per launch), CPU s per wall s (all threads of the process over the
wall time) and the calling thread's CPU ms per step; the table shows the median and the range over
`--rounds` rounds. A kernel that keeps both threads busy all the time reads 2.00; what the full step
loses against the kernels alone is the host's share, what the kernels lose against 2.00 is their own
(launches, waking the threads, serial parts inside the kernels, threads that finish their block early).
Writes section `ceiling` of docs/performance_wcsph.md (or `--out`, `--section`).

    python tools/bench_launch.py [--config configs/dambreak_wcsph.yaml] [--set dx=0.01] [--steps 300]
                                 [--rounds 5] [--threads 2]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench import machine
from bench_wcsph import _shown, load_average, replace_section


def timed(fn, steps: int, chunk: int, reset) -> dict:
    """Wall ms, CPU s / wall s and the calling thread's CPU ms, per call of fn, over `steps` calls made in
    chunks of `chunk`, each after reset() (not timed)."""
    wall = cpu = main = 0.0
    done = 0
    while done < steps:
        reset()
        k = min(chunk, steps - done)
        c0, m0, w0 = time.process_time(), time.thread_time(), time.perf_counter()
        for _ in range(k):
            fn()
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
        main += time.thread_time() - m0
        done += k
    return {"wall_ms": 1e3 * wall / steps, "cpu_over_wall": cpu / wall, "main_ms": 1e3 * main / steps}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "dambreak_wcsph.yaml"))
    ap.add_argument("--set", dest="overrides", action="append", default=None, metavar="KEY=VALUE",
                    help="config overrides (default dx=0.01)")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--chunk", type=int, default=10, help="calls between restores of the saved state")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance_wcsph.md"))
    ap.add_argument("--section", default="ceiling")
    args = ap.parse_args()
    overrides = args.overrides if args.overrides is not None else ["dx=0.01"]

    import taichi as ti

    from taichi_sph import backend
    from taichi_sph.config import load_config
    from taichi_sph.guard import StabilityGuard
    from taichi_sph.run import TimeStepper, _reference_density, _with_flag
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    be = backend.init("cpu", "auto", threads=args.threads, mode="wcsph_biot")
    cfg = load_config(args.config, overrides)
    scene = build_scene(cfg)
    solver = make_solver(cfg, scene)
    solver.initial_diagnostics()
    stepper = TimeStepper(cfg, solver.g_abs)
    guard = StabilityGuard(cfg, scene.kind, _reference_density(solver, scene.kind), solver.max_speed_bound(),
                           scene.body, scene.motions)
    guard.start(_with_flag(solver.fields_by_id()))

    def full():
        solver.step(stepper.choose(0.0, solver.propose_dt())[0])

    def full_and_guard():
        full()
        if guard.due(solver.step_count):
            guard.check_fields(solver.step_count, solver.time, solver.guard_fields())

    for _ in range(args.warmup):
        full()
    guard.check_fields(solver.step_count, solver.time, solver.guard_fields())  # compiles its gather kernel
    kick, pairs = solver._step_kernels
    n = solver.n
    scratch = ti.field(float, n)

    @ti.kernel
    def empty_loop():
        for i in range(n):
            scratch[i] += 1.0

    def bare_args():
        dt = stepper.choose(0.0, solver.propose_dt())[0]
        return dt, solver.dt_prev, *solver._weights(dt)

    def two_kernels():
        kick(dt, dt_prev, w1, w2, solver.red_kick)
        pairs(dt, solver.red_pairs)

    variants = {
        "full step": full,
        "full step and the guard": full_and_guard,
        "two kernels, no host work": two_kernels,
        "pair kernel alone": lambda: pairs(dt, solver.red_pairs),
        "kick-drift alone": lambda: kick(dt, dt_prev, w1, w2, solver.red_kick),
        "empty parallel loop": empty_loop,
    }
    empty_loop()
    saved = solver.state()
    dt, dt_prev, w1, w2 = bare_args()  # the step the solver takes next from the saved state

    def reset():
        solver.load_state(saved)

    load0 = load_average()
    rows = {name: [] for name in variants}
    for k in range(args.rounds):
        for name, fn in variants.items():
            # the full step runs on from the saved state as a run does (its list rebuilds at their own
            # pace); the kernels alone restart from it every chunk
            chunk = args.steps if name.startswith("full step") else args.chunk
            rows[name].append(timed(fn, args.steps, chunk, reset))
        print(f"round {k + 1}: " + ", ".join(f"{name} {r[-1]['cpu_over_wall']:.2f}" for name, r in rows.items()),
              flush=True)
    load1 = load_average()

    def cell(name, key, fmt):
        vals = [r[key] for r in rows[name]]
        return f"{format(statistics.median(vals), fmt)} ({format(min(vals), fmt)}-{format(max(vals), fmt)})"

    lines = [
        (f"Machine: {machine()}; Taichi {'.'.join(map(str, ti.__version__))}, {args.threads} threads, "
         f"{be['precision']}. Produced by `python tools/bench_launch.py` on {time.strftime('%Y-%m-%d')}: "
         f"{_shown(args.config)} ({' '.join(overrides)}), {solver.n_fluid} moving particles, {args.rounds} "
         f"rounds of {args.steps} calls each (chunks of {args.chunk} from one saved state) after {args.warmup} "
         f"full steps; the guard's field check every {guard.every} steps; load {load0:.1f} / {load1:.1f} "
         "(1-minute load average at the start / end). Median (range over the rounds)."),
        "",
        "| what runs | wall ms per call | CPU s / wall s | calling thread's CPU ms per call |",
        "|---|---|---|---|",
    ]
    for name in variants:
        lines.append(f"| {name} | {cell(name, 'wall_ms', '.3f')} | {cell(name, 'cpu_over_wall', '.2f')} | "
                     f"{cell(name, 'main_ms', '.3f')} |")
    text = "\n".join(lines) + "\n"
    print(text)
    replace_section(Path(args.out), args.section, text)
    print(f"wrote section {args.section} of {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
