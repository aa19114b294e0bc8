"""Start one `taichi-sph` command as a child of the forkserver (taichi_sph/cli_fork.py) and wait for it.
Kept apart from cli_fork.py so that the caller does not import what the server imports."""

from __future__ import annotations


def run(ctx, args: list[str], env: dict, cwd: str, out_path: str, err_path: str, timeout: float | None) -> int | None:
    """Exit code of the child (negative: the signal that killed it), None when `timeout` (s) ran out first:
    the child is then killed, as subprocess.run kills a process past its time-out."""
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


def _target(args, env, cwd, out_path, err_path):
    from .cli_fork import child_main

    child_main(args, env, cwd, out_path, err_path)
