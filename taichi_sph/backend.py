"""Taichi initialisation: architecture choice, precision, threads, offline cache."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from .errors import InputError

#: The offline cache's size limit in bytes. Taichi's default, 100 MB, holds about 3000 compiled kernels. A
#: kernel is compiled for the sizes of its scene (particle count, grid), so a set of scenes (a sweep over
#: dx, the test suite's few hundred scenes) outgrows that, and Taichi's least-recently-used cleaning then
#: deletes a quarter of the files at a process's exit: kernels that a later run of the same scene compiles
#: again, seconds each. The test suite's kernels alone take 527 MB (15,594 files from an empty cache,
#: 2026-11-29). Taichi holds the limit in a 32-bit int: at most 2 GiB - 1.
CACHE_MAX_BYTES = 1 << 30


#: Taichi 1.7's LLVM backends (CPU, CUDA) hold at most 512 SNode trees in one runtime, and the 513th
#: ends the process with a segmentation fault and no message. Fields declared between two kernel launches
#: form one tree, so a solver takes several: 2-11 while the shipped configs' solvers are built, 13 with the
#: multigrid PPE, and 3-4 more at the first step (measured 2026-11-29). A process that builds solver after
#: solver (a notebook, a test session) runs out after some tens of them; the CLI builds one per process.
MAX_FIELD_TREES = 512
#: the trees a solver is allowed to need, built and stepped: 3.5 times the most measured (17)
SOLVER_FIELD_TREES = 64


#: Taichi prints its banner on stdout when first imported unless this variable says 0
_TAICHI_BANNER = "ENABLE_TAICHI_HEADER_PRINT"


@contextlib.contextmanager
def no_taichi_banner():
    """Within: a first import of Taichi prints no banner on stdout (`info --json` prints nothing but JSON;
    the server of forked commands imports Taichi for them). The variable is restored afterwards."""
    before = os.environ.get(_TAICHI_BANNER)
    os.environ[_TAICHI_BANNER] = "0"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(_TAICHI_BANNER, None)
        else:
            os.environ[_TAICHI_BANNER] = before


def field_trees_used() -> int | None:
    """SNode trees the live Taichi runtime holds (MAX_FIELD_TREES), None where none is started."""
    from taichi.lang import impl

    prog = impl.get_runtime().prog
    return None if prog is None else prog.get_snode_tree_size()


def check_field_room() -> None:
    """Raise a one-line RuntimeError where the live Taichi runtime has too few SNode trees left for
    another solver (MAX_FIELD_TREES), instead of letting Taichi crash the process while it builds one."""
    used = field_trees_used()
    if used is None:
        return
    if used + SOLVER_FIELD_TREES > MAX_FIELD_TREES:
        raise RuntimeError(
            f"this Taichi runtime holds {used} of its {MAX_FIELD_TREES} field trees, too few left for another "
            f"solver ({SOLVER_FIELD_TREES}); build each case in its own process (as the CLI and sweeps do) or "
            "call ti.reset() and ti.init() before the next one")


def cpu_threads_per_worker(workers: int) -> int:
    """CPU threads for each of `workers` processes running at once: their share of the cores, at least 1
    (more would oversubscribe the machine, and a parallel loop then waits on parked threads)."""
    return max(1, (os.cpu_count() or 1) // max(1, int(workers)))


def _cache_dir() -> str:
    base = os.environ.get("TAICHI_SPH_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", str(Path.home() / ".cache")), "taichi-sph")
    return str(Path(base) / "ticache")


def taichi_options(cpu: bool = True) -> dict:
    """The `ti.init` arguments every runtime of the project takes: the offline cache's folder
    ($TAICHI_SPH_CACHE, else ~/.cache/taichi-sph) and size limit (CACHE_MAX_BYTES); on the CPU, Taichi's
    control-flow-graph pass off (`cfg_optimization`). That pass (store-to-load forwarding, dead stores
    over the kernel's control-flow graph) took a quarter of a cold compilation and bought no speed here
    (2026-11-28, this 2-core machine, one thread: the coarse free fall's 10 steps from an empty cache 16.0
    -> 12.1 s; its 200 steps 6.9 / 6.8 s, the wcsph dam break to 0.3 s 76.8 / 76.0 s with the pass on /
    off, warm; `tools/bench.py --no-jit --sizes S --dims 2 --baseline` against the code before, the same
    run, 2 threads: isph_porous 118.4 -> 113.7 ms/step, wcsph 2.6 -> 2.3 ms/step). Its absence moves the
    arithmetic at round-off (positions 7e-13 m after 200 steps). GPUs keep it: not measured there."""
    out = {"offline_cache": True, "offline_cache_file_path": _cache_dir(),
           "offline_cache_max_size_of_files": CACHE_MAX_BYTES}
    if cpu:
        out["cfg_optimization"] = False
    return out


def resolved_precision(precision: str, gpu: bool, mode: str | None) -> str:
    """The precision a run takes: `precision` itself unless it is 'auto', which means f32 on GPUs and in
    mode wcsph_biot, whose position, density and smoothing length stay f64 at either precision
    (docs/performance_wcsph.md, "Precision": f32 holds f64's accuracy on the hydrostatic tank, the dam
    break, Terzaghi and Dupuit, and is faster), and f64 for mode isph on the CPU, whose fields are all of
    the run's precision."""
    if precision != "auto":
        return precision
    return "f32" if gpu or mode == "wcsph_biot" else "f64"


def auto_precision(arch, mode: str | None) -> str:
    """What `precision: auto` means on Taichi backend `arch` (`resolved_precision`)."""
    import taichi as ti

    return resolved_precision("auto", arch != ti.cpu, mode)


def init(arch: str = "cpu", precision: str = "auto", threads: int | None = None, debug: bool = False,
         mode: str | None = None) -> dict:
    """Initialise Taichi once for this process. Returns {'arch': name, 'precision': 'f32'|'f64'}.
    `mode` (the config's) decides what `precision: auto` means (`auto_precision`)."""
    import taichi as ti

    from . import taichi_frontend

    taichi_frontend.install()
    names = {"cpu": [ti.cpu], "cuda": [ti.cuda], "vulkan": [ti.vulkan], "auto": [ti.cuda, ti.cpu]}
    chosen = None
    last_err = None
    for candidate in names[arch]:
        fp = precision
        if fp == "auto":
            fp = auto_precision(candidate, mode)
        kwargs = dict(arch=candidate, default_fp=ti.f64 if fp == "f64" else ti.f32, random_seed=0,
                      debug=debug, **taichi_options(candidate == ti.cpu),
                      log_level=os.environ.get("TI_LOG_LEVEL", "warn"))
        if candidate == ti.cpu and threads:
            kwargs["cpu_max_num_threads"] = int(threads)
        try:
            ti.init(**kwargs)
        except Exception as exc:  # noqa: BLE001
            last_err = exc
            continue
        actual = ti.lang.impl.current_cfg().arch
        if candidate != ti.cpu and actual == ti.cpu:
            # Taichi falls back to the CPU silently when the GPU backend is missing
            if arch != "auto":
                raise InputError(f"--arch {arch}: backend not available on this machine")
            ti.reset()
            continue
        chosen = (actual, fp)
        break
    if chosen is None:
        raise InputError(f"--arch {arch}: no usable Taichi backend ({last_err})")
    name = str(chosen[0]).split(".")[-1]
    return {"arch": "cpu" if name in ("x64", "arm64") else name, "precision": chosen[1]}


def ids_text(ids, limit: int = 10) -> str:
    """Particle ids for a message: the first `limit`, then how many in all."""
    ids = [int(i) for i in ids]
    text = ", ".join(str(i) for i in ids[:limit])
    return text + (f", ... ({len(ids)} in all)" if len(ids) > limit else "")


def on_cpu() -> bool:
    """Whether the initialised Taichi runtime runs on the CPU (x64 or arm64), not a GPU."""
    import taichi as ti

    return ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64)


def is_f64() -> bool:
    """Whether the initialised Taichi runtime computes in double precision."""
    import taichi as ti
    from taichi.lang import impl

    return impl.get_runtime().default_fp == ti.f64
