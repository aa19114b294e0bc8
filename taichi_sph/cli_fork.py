"""A `taichi-sph` command in a process forked from one that has already imported what the command needs.

A fresh `python -m taichi_sph.cli` spends about half a second importing Taichi, NumPy, h5py, pydantic
and this package before it reads its config, a quarter of a short run's start-up (docs/performance.md,
"Start-up of a command"). `taichi_sph.cli_process` starts its commands through Python's `forkserver`
(multiprocessing): one server process per caller imports this module once, and each command is a
child forked from it, which runs `cli.main` as `python -m taichi_sph.cli` would. Nothing of Taichi's
runtime exists in the server (no `ti.init`, no threads): each child starts its own, as a fresh process
does.

What a child does differently from a fresh process, and why it is the same for the command:

- Its standard output and error are the files it is given (both the same file for a log), rebound at
  the file-descriptor level, so that Taichi's C++ messages land there too (cli_fork_launch.py); stdin
  is /dev/null.
- It leaves with `os._exit` after `cli.main` returns (the exit code as a process would give it), after
  Taichi's runtime is reset, which writes the kernels it compiled to the offline cache as the end of a
  fresh process does, and after its threads that are not daemons have ended and the `atexit` handlers
  have run.
- Taichi's banner ("[Taichi] version ...") is not printed: the server imported Taichi with it off.
- Its modules are those the server imported when it started: source changed on disk after that
  reaches a forked command only from a new server (a new calling process).
"""

from __future__ import annotations

import atexit
import sys
import threading
import traceback

from .backend import no_taichi_banner

with no_taichi_banner():
    import h5py  # noqa: F401
    import numpy  # noqa: F401
    import taichi

    from . import cli, run, scene, solvers  # noqa: F401
    from .io import hdf5  # noqa: F401
    from .isph import solver as _isph_solver  # noqa: F401
    from .wcsph import solver as _wcsph_solver  # noqa: F401


def _exit_code(code) -> int:
    """The exit status Python gives `sys.exit(code)`."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def run_command(args: list[str]) -> int:
    """Run `taichi-sph ARGS` in this (forked) process, its output already where it belongs, and end what a
    process's exit would end (its threads, Taichi's runtime, the atexit handlers); returns the exit code."""
    sys.argv = [cli.__file__, *args]
    try:
        code = _exit_code(cli.main(args))
    except SystemExit as exc:
        code = _exit_code(exc.code)
    except BaseException:  # noqa: BLE001 - as an uncaught exception ends a process: traceback, status 1
        traceback.print_exc()
        code = 1
    _join_threads()
    _finish_taichi()
    atexit._run_exitfuncs()
    return code


def _join_threads() -> None:
    """Wait for the threads that are not daemons, as a process's end does before it exits."""
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join()


def _finish_taichi() -> None:
    """Reset Taichi's runtime where one was started: that writes its newly compiled kernels to the
    offline cache (a fresh process does it when its runtime is destroyed at exit)."""
    from taichi.lang import impl

    if impl.get_runtime().prog is not None:
        taichi.reset()
