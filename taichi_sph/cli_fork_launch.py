"""Start one `taichi-sph` command as a child of the forkserver (taichi_sph/cli_fork.py) and wait for it.
Kept apart from cli_fork.py so that the caller does not import what the server imports."""

from __future__ import annotations

import contextlib
import io
import os
import sys
import traceback


def run(ctx, args: list[str], env: dict, cwd: str, out_path: str, err_path: str, timeout: float | None) -> int | None:
    """Exit code of the child (negative: the signal that killed it), None when `timeout` (s) ran out first:
    the child is then killed, as subprocess.run kills a process past its time-out. The paths are
    absolute: the child starts in the server's working directory."""
    proc = ctx.Process(target=_target, args=(args, env, cwd, out_path, err_path), name="taichi-sph")
    proc.start()
    try:
        proc.join(timeout)
        if proc.exitcode is None:
            proc.kill()
            proc.join()
            return None
        return proc.exitcode
    except BaseException:  # interrupted while waiting: the command does not outlive its caller
        proc.kill()
        proc.join()
        raise
    finally:
        proc.close()


def _rebind(fd: int, path: str) -> None:
    target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(target, fd)
    os.close(target)


def _target(args, env, cwd, out_path, err_path):
    """In the child: its output files (at the file-descriptor level, so that Taichi's C++ messages land
    there too), working directory and environment, then the command (cli_fork.run_command); it leaves
    with os._exit and the command's exit code. Whatever fails before the command runs (a working
    directory that is gone, a package the server could not import) is a traceback in its error file
    and exit code 1."""
    code = 1
    try:
        _rebind(1, out_path)
        if err_path == out_path:
            os.dup2(1, 2)
        else:
            _rebind(2, err_path)
        encoding = sys.stdout.encoding if sys.stdout is not None else "utf-8"
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding=encoding)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), encoding=encoding,
                                      errors="backslashreplace", line_buffering=True)
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(env)
        from .cli_fork import run_command

        code = run_command(args)
    except BaseException:  # noqa: BLE001 - reported as a process reports what ends it
        traceback.print_exc()
        code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):  # a closed or broken stream: nothing more to say
                stream.flush()
        os._exit(code)
