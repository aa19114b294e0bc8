"""Throughput benchmark of mode wcsph_biot: particle-steps per second and wall seconds per simulated second.

Cases (`--case`, default all):
- dambreak_20k, dambreak_80k: configs/dambreak_wcsph.yaml (tank 4 m x 3 m, column 1 m x 2 m) at dx 1 cm
  and 5 mm;
- levee_saturated: the levee config given by `--levee` (default configs/embankment.yaml), variant
  `--saturated` (default none: the shipped config's stage 2, soil + water, a piston raising the river);
- levee_dry: the same config, variant `--dry` (the shipped one: soil + a river against the dry levee, no
  air; the earlier configs' `dry` variant held air in the levee's pores);
- dambreak3d_200k (on request): the dam break's 3d variant (a slice 0.2 m deep) at 200k water particles;
- levee_fine (on request): the saturated levee case at dx 4 mm, whose loops run in parallel.
The levee cases start from their K0 state (`wcsph.soil.start_from` cleared: the saturated stage otherwise
needs a stage-1 run file; the particles and passes are the same). Each case lets the flow start (warm-up,
JIT compilation excluded), then times `--steps` steps with the time step of eq 49 in ten chunks and
reports particle-steps per second (the particles that move: water, air, soil), wall and CPU seconds per
simulated second, CPU seconds per wall second of the timed loop (time.process_time against
time.perf_counter; 2 = both cores of a 2-thread run busy), the calling thread's CPU time per step (the
serial part: Python, kernel launches, host reads), the split between phases and how often neighbour
lists were rebuilt. Writes the section "bench" of docs/performance_wcsph.md (or `--section`) and
docs/performance_wcsph_bench.json.

    python tools/bench_wcsph.py [--case ...] [--steps 300] [--warmup 200] [--precision auto|f64|f32 ...]
                                [--levee configs/embankment.yaml --saturated VARIANT --dry dry]
    python tools/bench_wcsph.py --against /path/to/other/checkout --rounds 3 [...]

`--precision auto` (the default) is what a run of this mode gets without the key: f32 since it became the
default, f64 in a checkout from before. Each precision runs in its own process (one Taichi runtime per
process). With --against, the same cases (the same config files) also run with the package of another
checkout, alternating with this one `--rounds` times, so that both see the same machine load; the table
then gains the per-round CPU times and rates and their ratios, with the load average (os.getloadavg, 1
minute) at the start and end of each run. On a shared machine compare CPU time per step, not wall time:
a thread that waits for a core costs no CPU time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
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


#: the cases: name -> (config, variant, overrides, what it is). The levee cases read the config file and
#: variants given on the command line (--levee, --saturated, --dry); `start_from` is cleared so that the
#: saturated stage starts from its K0 state instead of a stage-1 run file (the same particles and passes).
DAM = "configs/dambreak_wcsph.yaml"


def case_table(args) -> dict:
    levee = str(Path(args.levee).resolve())
    saturated = f"{Path(levee).name} {('variant ' + args.saturated) if args.saturated else 'stage 2'}"
    return {
        "dambreak_20k": (str(ROOT / DAM), None, ["dx=0.01"], "2D dam break, dx 1 cm (20k water)"),
        "dambreak_80k": (str(ROOT / DAM), None, ["dx=0.005"], "2D dam break, dx 5 mm (80k water)"),
        # the 3d variant (column 1 x 0.2 x 2 m in a tank 4 x 0.2 x 3 m) at 200k water particles
        "dambreak3d_200k": (
            str(ROOT / DAM),
            "3d",
            [f"dx={(0.4 / 2e5) ** (1 / 3):.5f}"],
            "3D dam break, 0.2 m deep slice (200k water)",
        ),
        "levee_saturated": (
            levee,
            args.saturated or None,
            ["wcsph.soil.start_from=null"],
            f"levee, soil + water ({saturated})",
        ),
        "levee_dry": (
            levee,
            args.dry,
            ["wcsph.soil.start_from=null"],
            f"dry levee ({Path(levee).name} variant {args.dry})",
        ),
        # the same levee at dx 4 mm (16.8k moving particles in the shipped config): large enough that its
        # loops run in parallel (solver.SERIAL_BELOW_SOIL), so the threads' balance counts
        "levee_fine": (
            levee,
            args.saturated or None,
            ["wcsph.soil.start_from=null", "dx=0.004"],
            f"levee at dx 4 mm, soil + water ({saturated})",
        ),
    }


def bench_case(
    dx: float | None = None,
    steps: int = 300,
    warmup: int = 200,
    overrides=(),
    until: float | None = None,
    config: str | None = None,
    variant: str | None = None,
    reorder_every: int = 1,
) -> dict:
    """Time `steps` steps after `warmup` ones of `config` (default: the dam break, at spacing dx); with
    `until`, time every step from the warm-up on up to that simulated time instead (stability over a whole
    run: smallest and largest step, the surge front, i.e. the largest x of any water particle, at the end).
    Particle-steps count the particles that move (water, air, soil)."""
    from taichi_sph.config import load_config
    from taichi_sph.run import TimeStepper
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    sets = [*([f"dx={dx}"] if dx is not None else []), *overrides]
    cfg = load_config(config or CODE / DAM, sets, variant=variant)
    scene = build_scene(cfg)
    t0 = time.perf_counter()
    solver = make_solver(cfg, scene)
    if reorder_every != 1:
        solver.reorder_every = reorder_every
    solver.initial_diagnostics()
    stepper = TimeStepper(cfg, solver.g_abs)
    for _ in range(warmup):
        solver.step(stepper.choose(0.0, solver.propose_dt())[0])
    setup = time.perf_counter() - t0
    for k in solver.timers:
        solver.timers[k] = 0.0
    rebuilds0 = solver.rebuilds
    time0 = solver.time
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
        run_extra = {
            "dt_min": min(dts),
            "dt_max": max(dts),
            "front_x": float(solver.x.to_numpy()[:n][water, 0].max()),
            "tank_length": float(solver.cfg.tank.size[0]),
        }
    wall = sum(chunks)
    best = min(chunks[:-1] or chunks) / chunk  # the last chunk of a run to `until` may be short
    moving = solver.n_fluid + getattr(solver, "n_soil", 0)
    simulated = solver.time - time0
    return {
        "case": "dam break 2D",
        "dx": cfg.dx,
        "fluid_particles": solver.n_fluid,
        "soil_particles": getattr(solver, "n_soil", 0),
        "moving_particles": moving,
        "all_particles": solver.n,
        "steps": steps,
        "simulated_time_at_end": solver.time,
        "simulated_seconds": simulated,
        "seconds_per_step": wall / steps,
        "particle_steps_per_second": moving * steps / wall,
        "mipps": moving * steps / wall / 1e6,
        "mipps_best_chunk": moving / best / 1e6,
        "wall_seconds_per_simulated_second": wall / simulated if simulated > 0 else float("nan"),
        "cpu_seconds_per_simulated_second": cpu / simulated if simulated > 0 else float("nan"),
        "steps_per_simulated_second": steps / simulated if simulated > 0 else float("nan"),
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


def replace_section(path: Path, name: str, text: str) -> None:
    """Put `text` between the markers of section `name` in the markdown file `path` (appended at the end the
    first time), so that each tool regenerates its own part of a page and leaves the rest as written."""
    begin, end = f"<!-- {name}: generated, begin -->", f"<!-- {name}: generated, end -->"
    old = path.read_text() if path.exists() else ""
    block = f"{begin}\n{text.rstrip()}\n{end}"
    if begin in old and end in old:
        head, rest = old.split(begin, 1)
        new = head + block + rest.split(end, 1)[1]
    else:
        new = (old.rstrip() + "\n\n" if old else "") + block + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(new)


def _shown(path: str) -> str:
    """A config path as the tables show it: relative to the checkout when inside it, else its name."""
    p = Path(path).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else p.name


def load_average() -> float:
    """1-minute load average of the machine (processes running or waiting for a core)."""
    return os.getloadavg()[0]


PHASES = ("update", "neighbours", "pairs", "soil")


def markdown(results, info) -> str:
    lines = [
        (
            f"Machine: {info['machine']}; Taichi {info['taichi']}, arch {info['arch']}, {info['threads']} "
            f"threads. "
            f"Produced by `python tools/bench_wcsph.py` on {info['date']}"
            + (f" (overrides {' '.join(info['overrides'])})" if info.get("overrides") else "")
            + "."
        ),
        "",
        f"Each case timed over {info['steps']} steps after {info['warmup']} steps of warm-up (JIT "
        f"compilation "
        "excluded), adaptive step of eq 49. Particle-steps count the particles that move (water, air, soil). "
        "Wall s per simulated s = wall time per step / mean step. CPU s / wall s: all threads of the process "
        "over the wall time of the timed loop (2 = both cores busy with this run). CPU ms per step counts "
        "all "
        "threads; `main` is the calling thread's CPU time per step (Python, kernel launches, host reads, "
        "serial "
        "parts of kernels; Taichi's worker threads run the parallel loops). Load: the 1-minute load average "
        "at the start / end of the run (other processes on the machine). The phases are wall ms per step.",
        "",
        "| case | precision | moving particles | all particles | M particle-steps/s | (fastest tenth) | "
        "wall s per simulated s | steps per simulated s | CPU s / wall s | CPU ms/step | main ms/step | load "
        "| "
        "steps per list rebuild | " + " | ".join(PHASES) + " |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(PHASES),
    ]
    for r in results:
        ph = " | ".join(f"{1e3 * r['phase_seconds_per_step'].get(p, 0.0):.2f}" for p in PHASES)
        lines.append(
            f"| {r['name']} | {r['precision']} | {r['moving_particles']} | {r['all_particles']} | "
            f"{r['mipps']:.2f} | {r['mipps_best_chunk']:.2f} | "
            f"{r['wall_seconds_per_simulated_second']:.1f} | {r['steps_per_simulated_second']:.0f} | "
            f"{r['cpu_over_wall']:.2f} | {1e3 * r['cpu_seconds_per_step']:.2f} | "
            f"{1e3 * r['main_thread_cpu_seconds_per_step']:.2f} | "
            f"{r['load_start_end'][0]:.1f} / {r['load_start_end'][1]:.1f} | {r['steps_per_rebuild']:.1f} | "
            f"{ph} |"
        )
    return "\n".join(lines) + "\n"


def run_one(args) -> list:
    """The chosen cases at one precision, in this process."""
    global CODE
    if args.code:  # the package of another checkout
        CODE = Path(args.code).resolve()
        sys.path.insert(0, str(CODE))
    from taichi_sph import backend

    try:
        be = backend.init(args.arch, args.precision[0], mode="wcsph_biot")
    except TypeError:  # a checkout from before `precision: auto` depended on the mode (f64 on the CPU then)
        be = backend.init(args.arch, args.precision[0])
    table = case_table(args)
    results = []
    for name in args.case:
        config, variant, sets, what = table[name]
        load0 = load_average()
        r = bench_case(
            None,
            args.steps,
            args.warmup,
            [*sets, *args.overrides],
            config=config,
            variant=variant,
            reorder_every=args.reorder_every,
        )
        r.update(name=name, what=what, precision=be["precision"], load_start_end=[load0, load_average()])
        print(
            f"{name} {be['precision']}: {r['moving_particles']} moving particles, {r['mipps']:.2f} M "
            f"particle-steps/s "
            f"(fastest tenth {r['mipps_best_chunk']:.2f}), {r['wall_seconds_per_simulated_second']:.1f} wall "
            f"s per "
            f"simulated s, cpu/wall {r['cpu_over_wall']:.2f}, CPU {1e3 * r['cpu_seconds_per_step']:.2f} "
            f"ms/step, main "
            f"{1e3 * r['main_thread_cpu_seconds_per_step']:.2f} ms/step, {r['steps_per_rebuild']:.1f} steps "
            f"per "
            f"rebuild, load {r['load_start_end'][0]:.1f} / {r['load_start_end'][1]:.1f}",
            flush=True,
        )
        results.append(r)
    return results


def child(tree: Path, prec: str, args, path: Path) -> list:
    """One precision, every case, in a process of its own with the code of checkout `tree`."""
    cmd = [
        sys.executable,
        __file__,
        "--precision",
        prec,
        "--results-json",
        str(path),
        "--code",
        str(tree),
        "--arch",
        args.arch,
        "--steps",
        str(args.steps),
        "--warmup",
        str(args.warmup),
        "--case",
        *args.case,
        "--levee",
        str(Path(args.levee).resolve()),
        "--saturated",
        args.saturated,
        "--dry",
        args.dry,
    ]
    if args.reorder_every != 1:
        cmd += ["--reorder-every", str(args.reorder_every)]
    for o in args.overrides:
        cmd += ["--set", o]
    subprocess.run(cmd, check=True, env=dict(os.environ, PYTHONPATH=str(tree)))
    return json.loads(path.read_text())


def describe_checkout(path: str) -> str:
    """`commit <sha>` of a git checkout (its folder name when git cannot tell), for the tables."""
    try:
        sha = subprocess.run(
            ["git", "-C", str(path), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        return f"commit {sha}"
    except (OSError, subprocess.CalledProcessError):
        return Path(path).name


def comparison_markdown(rounds, against: str) -> str:
    """Rounds of (this checkout, the other) run back to back: CPU time per step, rates and their ratios."""
    lines = [
        f"Interleaved with the code of {against} (the other checkout), round by round, same cases: CPU ms "
        f"per "
        "step (all threads) and the main thread's, CPU s / wall s, M particle-steps/s, the 1-minute load "
        "average at the start / end of each run, and the ratios other / this of the CPU time per step "
        "(the measure that other processes disturb least) and this / other of the wall-clock rate.",
        "",
        "| case | precision (this / other) | round | this: CPU ms/step | main | CPU/wall | M p-steps/s | load | "
        "other: CPU ms/step | main | CPU/wall | M p-steps/s | load | CPU ratio | rate ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ratios = {}
    for k, (new, old) in enumerate(rounds):
        for a, b in zip(new, old):
            ratio, cratio = a["mipps"] / b["mipps"], b["cpu_seconds_per_step"] / a["cpu_seconds_per_step"]
            prec = a["precision"] if a["precision"] == b["precision"] else f"{a['precision']} / {b['precision']}"
            ratios.setdefault((a["name"], prec), []).append((cratio, ratio))
            la, lb = a["load_start_end"], b["load_start_end"]
            lines.append(
                f"| {a['name']} | {prec} | {k + 1} | {1e3 * a['cpu_seconds_per_step']:.2f} | "
                f"{1e3 * a['main_thread_cpu_seconds_per_step']:.2f} | {a['cpu_over_wall']:.2f} | "
                f"{a['mipps']:.2f} | {la[0]:.1f} / {la[1]:.1f} | {1e3 * b['cpu_seconds_per_step']:.2f} | "
                f"{1e3 * b['main_thread_cpu_seconds_per_step']:.2f} | {b['cpu_over_wall']:.2f} | "
                f"{b['mipps']:.2f} | {lb[0]:.1f} / {lb[1]:.1f} | {cratio:.2f} | {ratio:.2f} |"
            )
    for (name, prec), r in ratios.items():
        med = [statistics.median(x) for x in zip(*r)]
        lines.append(f"| {name} | {prec} | median | | | | | | | | | | | {med[0]:.2f} | {med[1]:.2f} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "--case",
        nargs="+",
        default=["dambreak_20k", "dambreak_80k", "levee_saturated", "levee_dry"],
        choices=["dambreak_20k", "dambreak_80k", "dambreak3d_200k", "levee_saturated", "levee_dry", "levee_fine"],
    )
    ap.add_argument(
        "--levee", default=str(ROOT / "configs" / "embankment.yaml"), help="config of the levee cases"
    )
    ap.add_argument("--saturated", default="",
                    help="its variant with soil and water (default none: the shipped config's stage 2)")
    ap.add_argument("--dry", default="dry", help="its dry-levee variant")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument(
        "--reorder-every",
        type=int,
        default=1,
        help="put the particles into cell order at every K-th list build only (solver.reorder_every)",
    )
    ap.add_argument("--precision", nargs="+", default=["auto"], choices=["auto", "f32", "f64"])
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance_wcsph.md"))
    ap.add_argument("--section", default="bench", help="section of --out that the tables replace")
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

    info = {
        "machine": machine(),
        "taichi": ".".join(map(str, ti.__version__)),
        "arch": args.arch,
        "threads": os.environ.get("TI_CPU_MAX_NUM_THREADS", os.cpu_count()),
        "date": time.strftime("%Y-%m-%d"),
        "warmup": args.warmup,
        "steps": args.steps,
        "overrides": args.overrides,
        "levee": _shown(args.levee),
    }
    out = Path(args.out)
    info["against"] = describe_checkout(args.against) if args.against else None
    payload = {"info": info, "results": results, "rounds": rounds}
    out.with_name(f"{out.stem}_{args.section}.json").write_text(json.dumps(payload, indent=1))
    text = markdown(results, info)
    if rounds:
        text += "\n" + comparison_markdown(rounds, info["against"])
    replace_section(out, args.section, text)
    print(f"wrote section {args.section} of {out}")


if __name__ == "__main__":
    main()
