"""Throughput benchmark matrix: mode x dimension x size x arch.

Modes: isph_free (hydrostatic tank at rest), isph_porous (the seed's free fall into a porous layer,
configs/freefall.yaml geometry, Smagorinsky on), wcsph (the dam break of configs/dambreak_wcsph.yaml,
tank 4 x 3 m, column 1 x 2 m; in 3D 0.2 m wide), wcsph_soil (a hook: listed, skipped until that
mode exists). Sizes S, M, L are about 10k, 50k and 200k water particles (dx chosen from the water
volume); XL, about 1M, is for GPUs; XS, about 2k, is a small case on a laptop (and the scale of the test
suite), where a step's loops run serially on the CPU when the scene, walls included, is small enough (isph
SERIAL_PARTICLES, wcsph SERIAL_BELOW). Each case runs in its own process (one Taichi runtime per
process), which gives:

- particle-steps per second (water particles x steps / wall seconds; MIPPS = millions of them),
- time per phase (the solver's own timers) and PPE CG iterations per step (isph),
- JIT time: setup and the first step less one steady step. For the smallest size of each mode and
  dimension one step runs with an empty Taichi offline cache (cold JIT) and again with it filled
  (warm JIT); the timed runs use the project cache directory `.cache/bench` (field sizes are
  compile-time constants, so each size has its own cache entries),
- peak memory: the largest resident set of the process (ru_maxrss); on CUDA also the device memory the
  case took (the GPU's used memory at the end of the case less before Taichi started, from nvidia-smi).

Writes docs/performance.json and the generated table into docs/performance.md between the markers
`<!-- bench:begin -->` and `<!-- bench:end -->` (the rest of that file is kept), machine named.

    python tools/bench.py --quick             # size S, 2D and 3D, every mode (a few minutes on 2 cores)
    python tools/bench.py [--modes ...] [--dims 2 3] [--sizes XS S M L XL] [--arch cpu cuda] [--min-time 10]
        [--no-jit]   # skip the cold / warm JIT runs of the smallest size
    python tools/bench.py --sizes XS S --baseline CHECKOUT --out compare.md
        # each case also runs on the package of another checkout (e.g. a git worktree of the commit before
        # a change), back to back with this one; the report gives the baseline's ms/step and the ratio
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SIZES = {"XS": 2_000, "S": 10_000, "M": 50_000, "L": 200_000, "XL": 1_000_000}
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"


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


def gpu_memory_used_mb() -> float | None:
    """The first GPU's used memory (MB) from nvidia-smi, or None without one."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                             capture_output=True, text=True, timeout=30, check=False).stdout.split()
        return float(out[0]) if out else None
    except (OSError, subprocess.SubprocessError, ValueError):
        return None


def gpu_name() -> str | None:
    """The first GPU's name, memory and driver from nvidia-smi, or None without one."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,driver_version", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=30, check=False).stdout.strip()
        return out.splitlines()[0] if out else None
    except (OSError, subprocess.SubprocessError):
        return None


# ---------------------------------------------------------------------------------------- cases
def _box(lo, hi):
    return {"min": list(lo), "max": list(hi)}


def _dx_for(volume: float, dim: int, target: int) -> float:
    return round((volume / target) ** (1.0 / dim), 6)


def isph_free(dim: int, target: int) -> dict:
    """Hydrostatic tank at rest (water 0.4 x 0.3 m in 2D, 0.4 x 0.2 x 0.3 m in 3D), dt 1 ms."""
    if dim == 2:
        size, water = [0.4, 0.4], _box([0, 0], [0.4, 0.3])
    else:
        size, water = [0.4, 0.2, 0.4], _box([0, 0, 0], [0.4, 0.2, 0.3])
    vol = 0.12 if dim == 2 else 0.024
    return {"mode": "isph", "dim": dim, "dx": _dx_for(vol, dim, target), "end_time": 1.0, "dt": 0.001,
            "tank": {"size": size}, "water": [water]}


def isph_porous(dim: int, target: int) -> dict:
    """configs/freefall.yaml: water 0.2 m (square or cube) falling onto a porous layer, eps0 0.3."""
    from taichi_sph.config.load import read_yaml

    data = read_yaml(ROOT / "configs" / "freefall.yaml")
    data.pop("variants", None)
    data.pop("output", None)
    data["dt"] = 0.001
    if dim == 2:
        data["dim"] = 2
        data["tank"]["size"] = [0.20, 0.70]
        data["water"] = [_box([0.0, 0.40], [0.20, 0.60])]
        data["soil"]["regions"][0].update(_box([0.0, 0.20], [0.20, 0.40]))
    vol = 0.2**dim
    data["dx"] = _dx_for(vol, dim, target)
    return data


def wcsph(dim: int, target: int) -> dict:
    """configs/dambreak_wcsph.yaml (column 1 x 2 m; 3D: 0.2 m wide), adaptive step of eq 49."""
    from taichi_sph.config.load import read_yaml

    data = read_yaml(ROOT / "configs" / "dambreak_wcsph.yaml")
    data.pop("variants", None)
    data.pop("output", None)
    if dim == 3:
        data["dim"] = 3
        data["tank"]["size"] = [4.0, 0.2, 3.0]
        data["water"] = [_box([0, 0, 0], [1.0, 0.2, 2.0])]
    vol = 2.0 if dim == 2 else 0.4
    data["dx"] = _dx_for(vol, dim, target)
    return data


MODES = {
    "isph_free": isph_free,
    "isph_porous": isph_porous,
    "wcsph": wcsph,
    # hook: soil-water coupling of mode wcsph_biot, added here once that mode runs
    "wcsph_soil": None,
}


# ---------------------------------------------------------------------------------------- one case (child)
def run_case(spec: dict) -> dict:
    """Build the scene and solver, time the first step (JIT) and then steps for `min_time` seconds."""
    from taichi_sph import backend
    from taichi_sph.config import load_config
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    gpu_before = gpu_memory_used_mb() if spec["arch"] == "cuda" else None
    be = backend.init(spec["arch"], spec.get("precision", "auto"))
    data = MODES[spec["mode"]](spec["dim"], spec["target"])
    for key, value in spec.get("set", {}).items():
        from taichi_sph.config.load import set_dotted

        set_dotted(data, key, value)
    cfg = load_config(data=data)
    scene = build_scene(cfg)
    t0 = time.perf_counter()
    solver = make_solver(cfg, scene)
    solver.initial_diagnostics()
    stepper = None
    if solver.proposes_dt:
        from taichi_sph.run import TimeStepper

        stepper = TimeStepper(cfg, solver.g_abs)

    def step():
        dt = cfg.dt if stepper is None else stepper.choose(0.0, solver.propose_dt())[0]
        return solver.step(dt)

    step()
    first = time.perf_counter() - t0
    for _ in range(spec.get("warmup", 2)):
        step()
    for k in solver.timers:
        solver.timers[k] = 0.0
    if spec.get("kernel_profile"):
        import taichi as ti

        ti.sync()
        ti.profiler.clear_kernel_profiler_info()
    iters = []
    steps = 0
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    while steps < spec.get("max_steps", 1000):
        last = step()
        iters.append(last.get("cg_iterations", 0))
        steps += 1
        if time.perf_counter() - t0 >= spec.get("min_time", 10.0) and steps >= 3:
            break
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    profile = kernel_profile(steps, spec["kernel_profile"]) if spec.get("kernel_profile") else None
    n_water = solver.n_water or solver.n_fluid
    per_step = wall / steps
    return {
        **{k: spec[k] for k in ("mode", "dim", "size", "arch")}, "precision": be["precision"],
        "arch_used": be["arch"], "dx": cfg.dx, "water_particles": int(n_water), "all_particles": int(solver.n),
        "ppe": cfg.isph.ppe.type if cfg.mode == "isph" else None,
        "steps": steps, "seconds_per_step": per_step, "particle_steps_per_second": n_water / per_step,
        "mipps": n_water / per_step / 1e6, "cpu_over_wall": cpu / wall,
        "cg_iterations_mean": sum(iters) / len(iters) if cfg.mode == "isph" else None,
        "phase_seconds_per_step": {k: v / steps for k, v in solver.timers.items()},
        "jit_seconds": max(first - per_step, 0.0),
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "device_memory_mb": (gpu_memory_used_mb() - gpu_before) if gpu_before is not None else None,
        **({"kernel_profile": profile} if profile is not None else {}),
    }


def kernel_profile(steps: int, top: int) -> list:
    """The `top` offloaded tasks (a kernel's parallel loops, each launched on its own) that took the most
    device time over the timed steps, from Taichi's kernel profiler (on while TI_KERNEL_PROFILER=1; on
    CUDA it times each task with events, so the steps themselves run somewhat slower): per task its
    milliseconds and launches per step, and its share of all the tasks' time."""
    import taichi as ti
    from taichi.profiler.kernel_profiler import get_default_kernel_profiler

    ti.sync()
    prof = get_default_kernel_profiler()
    prof._update_records()  # Taichi 1.7 keeps the per-task table private
    prof._count_statistics()
    stats = prof._statistical_results
    total = sum(v.total_time for v in stats.values()) or 1.0
    rows = sorted(stats.items(), key=lambda kv: -kv[1].total_time)[:top]
    return [{"task": name, "ms_per_step": v.total_time / steps, "launches_per_step": v.counter / steps,
             "share": v.total_time / total} for name, v in rows]


def spawn(spec: dict, cache: Path, src: Path | None = None) -> dict:
    """Run one case in a child process; `src`: import the package of that checkout instead of this one."""
    env = dict(os.environ, TAICHI_SPH_CACHE=str(cache), TI_LOG_LEVEL="error")
    if spec.get("kernel_profile"):
        env["TI_KERNEL_PROFILER"] = "1"
    with tempfile.NamedTemporaryFile(suffix=".json") as f:
        cmd = [sys.executable, __file__, "--child", json.dumps(spec), "--child-out", f.name]
        if src is not None:
            cmd += ["--child-src", str(src)]
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        if r.returncode != 0:
            tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["?"]
            return {**spec, "error": f"exit {r.returncode}: {tail[0]}"}
        return json.loads(Path(f.name).read_text())


# ---------------------------------------------------------------------------------------- report
def markdown(results, info) -> str:
    gpu = f" GPU: {info['gpu']}." if info.get("gpu") else ""
    lines = [
        (f"Machine: {info['machine']};{gpu} Taichi {info['taichi']}, {info['threads']} CPU threads, load average "
         f"{info['load']:.1f} at start. Produced by `python tools/bench.py {info['args']}` on {info['date']}."),
        "",
        ("| mode | dim | size | arch | precision | dx | water particles | M particle-steps/s | ms/step | CG iters "
         "| CPU s / wall s | JIT s (cold / warm) | peak memory MB | GPU memory MB | ms per phase |"),
        "|---|---|---|---|---|---|---:|---:|---:|---:|---:|---|---:|---:|---|",
    ]
    for r in results:
        label = r["mode"] + (f" ({r['ppe']})" if r.get("ppe") else "")
        head = f"| {label} | {r['dim']}D | {r['size']} | {r['arch']} "
        if "error" in r:
            lines.append(head + f"| | | | | | | | | | | not run: {r['error']} |")
            continue
        jit = f"{r['jit_seconds']:.1f}"
        if "jit_cold_seconds" in r:
            jit = f"{r['jit_cold_seconds']:.1f} / {r['jit_seconds']:.1f}"
        cg = "" if r["cg_iterations_mean"] is None else f"{r['cg_iterations_mean']:.0f}"
        ph = ", ".join(f"{k} {1e3 * v:.1f}" for k, v in r["phase_seconds_per_step"].items() if v > 0)
        gpu_mem = "" if r.get("device_memory_mb") is None else f"{r['device_memory_mb']:.0f}"
        lines.append(head + f"| {r['precision']} | {r['dx']:g} | {r['water_particles']} | {r['mipps']:.3f} | "
                     f"{1e3 * r['seconds_per_step']:.1f} | {cg} | {r['cpu_over_wall']:.2f} | {jit} | "
                     f"{r['peak_memory_mb']:.0f} | {gpu_mem} | {ph} |")
    based = [r for r in results if r.get("baseline_seconds_per_step")]
    if based:
        lines += ["", f"Against the baseline `{info.get('baseline')}`, each case run back to back with it: "
                  + "; ".join(f"{r['mode']} {r['dim']}D {r['size']} {r['arch']} "
                              f"{1e3 * r['baseline_seconds_per_step']:.1f} -> {1e3 * r['seconds_per_step']:.1f} ms/step "
                              f"({r['baseline_seconds_per_step'] / r['seconds_per_step']:.2f}x)" for r in based) + "."]
    jits = [r for r in results if "baseline_jit_seconds" in r]
    if jits:
        lines += ["", "JIT against the baseline (cold / warm, the baseline's first): "
                  + "; ".join(f"{r['mode']} {r['dim']}D {r['size']} {r['arch']} {r['baseline_jit_cold_seconds']:.2f} / "
                              f"{r['baseline_jit_seconds']:.2f} -> {r['jit_cold_seconds']:.2f} / {r['jit_seconds']:.2f} s"
                              for r in jits) + "."]
    return "\n".join(lines)


def _key(r) -> tuple:
    return (r["mode"], r.get("ppe") or "", r["dim"], r["size"], r["arch"])


def merged(old: list, new: list) -> list:
    """The new results, plus the old ones of cases not run this time, in matrix order."""
    keys = {_key(r) for r in new}
    rows = [r for r in old if _key(r) not in keys] + list(new)
    modes, sizes = list(MODES), list(SIZES)
    return sorted(rows, key=lambda r: (r["arch"], modes.index(r["mode"]), r.get("ppe") or "", r["dim"],
                                       sizes.index(r["size"])))


def write_report(out: Path, results, info, keep: bool = False) -> None:
    """JSON beside `out` and the table between the markers; `keep`: merge with the cases already there."""
    out.parent.mkdir(parents=True, exist_ok=True)
    js = out.with_suffix(".json")
    if keep and js.exists():
        old = json.loads(js.read_text())
        results = merged(old.get("results", []), results)
        info = {**info, "args": f"{old.get('info', {}).get('args', '')}; then {info['args']}"}
    js.write_text(json.dumps({"info": info, "results": results}, indent=2))
    replace_block(out, BEGIN, END, markdown(results, info))


def replace_block(path: Path, begin: str, end: str, body: str) -> None:
    """Put `body` between the markers `begin` and `end` of the Markdown file `path` (the rest of the file
    kept), or append the markers and body where the file has none."""
    block = f"{begin}\n{body}\n{end}"
    text = path.read_text() if path.exists() else "# Performance\n\n"
    if begin in text and end in text:
        text = text[: text.index(begin)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    path.write_text(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="size S only")
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    ap.add_argument("--dims", nargs="+", type=int, default=[2, 3], choices=[2, 3])
    ap.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES))
    ap.add_argument("--arch", nargs="+", default=["cpu"], choices=["cpu", "cuda"])
    ap.add_argument("--ppe", nargs="+", default=[None], choices=["sparse_cg", "ell_pcg", "mg_pcg"],
                    help="isph PPE solver types to run, each case with each in turn (default: the config's)")
    ap.add_argument("--min-time", type=float, default=10.0, help="seconds of timed steps per case")
    ap.add_argument("--no-jit", action="store_true", help="skip the cold / warm JIT runs of the smallest size")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="config override for every case, e.g. isph.ppe.type=sparse_cg")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance.md"))
    ap.add_argument("--keep", action="store_true", help="keep the cases already in the report that this run "
                    "does not repeat (add sizes or modes to an earlier run)")
    ap.add_argument("--kernel-profile", type=int, default=0, metavar="N",
                    help="print each case's N offloaded tasks that took the most device time per step (Taichi's "
                         "kernel profiler; it slows the steps, so the throughput of such a run is not the "
                         "benchmark's)")
    ap.add_argument("--baseline", type=Path, default=None, metavar="CHECKOUT",
                    help="also run each case on the package of this checkout, back to back with this one (the "
                         "timed run of the baseline first), and report its ms/step and the ratio")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--child-out", help=argparse.SUPPRESS)
    ap.add_argument("--child-src", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        if args.child_src:  # before anything imports the package
            sys.path.insert(0, str(Path(args.child_src).resolve()))
        Path(args.child_out).write_text(json.dumps(run_case(json.loads(args.child))))
        return 0
    if args.baseline is not None and not (args.baseline / "taichi_sph" / "__init__.py").is_file():
        print(f"error: --baseline {args.baseline}: no taichi_sph package there", file=sys.stderr)
        return 2
    from taichi_sph.config.load import parse_overrides

    overrides = dict(parse_overrides(args.overrides))
    sizes = ["S"] if args.quick else args.sizes
    cache = ROOT / ".cache" / "bench"
    load = os.getloadavg()[0]
    results = []
    for arch in args.arch:
        for mode in args.modes:
            for dim in args.dims:
                for size in sizes:
                    spec = {"mode": mode, "dim": dim, "size": size, "arch": arch, "target": SIZES[size],
                            "min_time": args.min_time, "set": overrides, "kernel_profile": args.kernel_profile}
                    if MODES[mode] is None:
                        results.append({**spec, "error": "mode not implemented yet"})
                        continue
                    ppes = args.ppe if mode.startswith("isph") else [None]
                    for ppe in ppes:  # back to back, so that load from elsewhere hits them alike
                        pspec = spec if ppe is None else {**spec, "set": {**overrides, "isph.ppe.type": ppe}}
                        jit = base_jit = None
                        if size == sizes[0] and not args.no_jit:
                            # one step with an empty offline cache (cold JIT), then again with it filled (warm);
                            # the baseline's the same way, first, in a cache of its own
                            one = {**pspec, "min_time": 0.0, "max_steps": 1, "warmup": 0, "kernel_profile": 0}
                            if args.baseline is not None:
                                with tempfile.TemporaryDirectory() as tmp:
                                    base_jit = [spawn(one, Path(tmp), args.baseline) for _ in range(2)]
                            with tempfile.TemporaryDirectory() as tmp:
                                jit = [spawn(one, Path(tmp)) for _ in range(2)]
                        base = None
                        if args.baseline is not None:
                            base = spawn(pspec, cache / "baseline", args.baseline)
                        r = spawn(pspec, cache)
                        if base is not None and "error" not in base and "error" not in r:
                            r["baseline_seconds_per_step"] = base["seconds_per_step"]
                        if jit is not None and not any("error" in j for j in (*jit, r)):
                            r["jit_cold_seconds"] = jit[0]["jit_seconds"]
                            r["jit_seconds"] = jit[1]["jit_seconds"]
                            if base_jit is not None and not any("error" in j for j in base_jit):
                                r["baseline_jit_cold_seconds"] = base_jit[0]["jit_seconds"]
                                r["baseline_jit_seconds"] = base_jit[1]["jit_seconds"]
                        results.append(r)
                        msg = r.get("error") or (f"{r['water_particles']} particles, {r['mipps']:.3f} M particle-steps/s, "
                                                 f"{1e3 * r['seconds_per_step']:.1f} ms/step")
                        if r.get("baseline_seconds_per_step"):
                            msg += (f" (baseline {1e3 * r['baseline_seconds_per_step']:.1f} ms/step, "
                                    f"{r['baseline_seconds_per_step'] / r['seconds_per_step']:.2f}x)")
                        if "baseline_jit_seconds" in r:
                            msg += (f"; JIT cold / warm {r['baseline_jit_cold_seconds']:.2f} / "
                                    f"{r['baseline_jit_seconds']:.2f} s -> {r['jit_cold_seconds']:.2f} / "
                                    f"{r['jit_seconds']:.2f} s")
                        print(f"{mode} {ppe or ''} {dim}D {size} {arch}: {msg}", flush=True)
                        for row in r.get("kernel_profile", []):
                            print(f"    {row['ms_per_step']:9.3f} ms/step {row['launches_per_step']:6.2f} launches/step "
                                  f"{100 * row['share']:5.1f} %  {row['task']}", flush=True)
    import taichi as ti

    info = {"machine": machine(), "gpu": gpu_name() if "cuda" in args.arch else None, "taichi": ".".join(map(str, ti.__version__)),
            "threads": os.environ.get("TI_CPU_MAX_NUM_THREADS", os.cpu_count()), "load": load,
            "date": time.strftime("%Y-%m-%d"), "args": " ".join(argv if argv is not None else sys.argv[1:]),
            **({"baseline": str(args.baseline)} if args.baseline is not None else {})}
    write_report(Path(args.out), results, info, keep=args.keep)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
