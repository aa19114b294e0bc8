"""One `taichi-sph` command in a process of its own (Taichi's state is per process), as `taichi-sph
sweep` runs its cases and tools/validate.py and tools/stress.py run theirs: the exit code, the output,
the one-line message that explains a failure, and the wall time of the process.

With TAICHI_SPH_FORK=1 in the caller's environment, and where Python's `forkserver` start method
exists (Linux, macOS), the process is forked instead from a server that has imported Taichi and this
package once (taichi_sph/cli_fork.py): each command then skips about half a second of imports. As with
any `multiprocessing` start method but `fork`, the caller's main module is imported again in each
child, so a script that sets the variable must keep its work under `if __name__ == "__main__":`; the
test suite sets it. Otherwise, and always in a daemonic process (which may not have children of its
own, as a Dask worker), a command is a fresh `python -m taichi_sph.cli`."""

from __future__ import annotations

import errno
import multiprocessing
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

PREFIX = "taichi-sph: "
#: beginnings of the lines that say why a run failed
FAILED = (PREFIX + "error", PREFIX + "unstable", PREFIX + "timed out")


@dataclass
class CliRun:
    rc: int  # exit code; negative: killed by that signal; -1 also when the time limit stopped it
    output: str  # what the process printed (stdout and stderr together)
    seconds: float  # wall time of the process

    def failure_line(self) -> str:
        """The line that explains the end of the run: the last error, instability or time-out line, else
        the last `taichi-sph:` line, else the last line printed ("" if none)."""
        lines = [ln.strip() for ln in self.output.splitlines() if ln.strip()]
        for wanted in (FAILED, (PREFIX,)):
            ours = [ln for ln in lines if ln.startswith(wanted)]
            if ours:
                return ours[-1]
        return lines[-1][-300:] if lines else ""

    @property
    def message(self) -> str:
        """`failure_line` without its `taichi-sph: ` prefix."""
        return self.failure_line().removeprefix(PREFIX)


#: the forkserver context once made (False where the platform has none); guarded by the lock
_CONTEXT = None
_CONTEXT_LOCK = threading.Lock()


def _fork_context():
    """The forkserver context whose children start with the CLI's modules imported, or None where
    commands start as fresh processes (see the module's docstring)."""
    global _CONTEXT
    if os.environ.get("TAICHI_SPH_FORK", "0") != "1" or multiprocessing.current_process().daemon:
        return None
    with _CONTEXT_LOCK:
        if _CONTEXT is None:
            if "forkserver" not in multiprocessing.get_all_start_methods():
                _CONTEXT = False
            else:
                ctx = multiprocessing.get_context("forkserver")
                ctx.set_forkserver_preload(["taichi_sph.cli_fork", "taichi_sph.cli_fork_launch"])
                _CONTEXT = ctx
    return _CONTEXT or None


def run_to_files(args, out_path, err_path, *, env: dict | None = None, cwd: str | Path | None = None,
                 timeout: float | None = None) -> int | None:
    """Run `taichi-sph ARGS...` with its standard output in `out_path` and its standard error in
    `err_path` (the same path for both: one file, in the order written). Returns the exit code
    (negative: killed by that signal), None when `timeout` (s) stopped it (it is killed). A `cwd` that
    is not a directory raises FileNotFoundError before anything starts, forked or fresh."""
    env = dict(os.environ if env is None else env)
    cwd = os.path.abspath(cwd) if cwd is not None else os.getcwd()
    if not os.path.isdir(cwd):
        raise FileNotFoundError(errno.ENOENT, "no such directory to run taichi-sph in", cwd)
    args = [str(a) for a in args]
    out_path, err_path = os.path.abspath(out_path), os.path.abspath(err_path)
    ctx = _fork_context()
    if ctx is not None:
        from . import cli_fork_launch

        return cli_fork_launch.run(ctx, args, env, cwd, out_path, err_path, timeout)
    cmd = [sys.executable, "-m", "taichi_sph.cli", *args]
    with open(out_path, "w", encoding="utf-8") as out:
        err = out if err_path == out_path else open(err_path, "w", encoding="utf-8")  # noqa: SIM115
        try:
            return subprocess.run(cmd, stdout=out, stderr=err if err is not out else subprocess.STDOUT, env=env,
                                  cwd=cwd, timeout=timeout, check=False).returncode
        except subprocess.TimeoutExpired:
            return None
        finally:
            if err is not out:
                err.close()


def _read(path) -> str:
    """The text of an output file; "" where the process never made it (killed before it started)."""
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return ""


def run_cli(args, *, log_path: str | Path | None = None, env: dict | None = None, cwd: str | Path | None = None,
            timeout: float | None = None) -> CliRun:
    """`taichi-sph ARGS...` (run_to_files); the output goes to `log_path` (and is read back from it) or
    is captured."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="taichi-sph-run-") as tmp:
        path = Path(log_path) if log_path is not None else Path(tmp) / "output.txt"
        rc = run_to_files(args, path, path, env=env, cwd=cwd, timeout=timeout)
        if rc is None:
            rc = -1
            with open(path, "a", encoding="utf-8") as logf:
                logf.write(f"{PREFIX}timed out after {timeout:g} s\n")
        output = _read(path)
    return CliRun(rc, output, time.perf_counter() - t0)


def run_cli_captured(args, *, env: dict | None = None, cwd: str | Path | None = None,
                     timeout: float | None = None) -> subprocess.CompletedProcess:
    """`taichi-sph ARGS...` (run_to_files) as `subprocess.run(..., capture_output=True, text=True)` gives
    it: stdout and stderr apart; raises subprocess.TimeoutExpired when `timeout` stopped it."""
    with tempfile.TemporaryDirectory(prefix="taichi-sph-run-") as tmp:
        out, err = Path(tmp) / "stdout.txt", Path(tmp) / "stderr.txt"
        rc = run_to_files(args, out, err, env=env, cwd=cwd, timeout=timeout)
        stdout, stderr = _read(out), _read(err)
    cmd = ["taichi-sph", *map(str, args)]
    if rc is None:
        raise subprocess.TimeoutExpired(cmd, timeout, output=stdout, stderr=stderr)
    return subprocess.CompletedProcess(cmd, rc, stdout, stderr)


def run_case_cli(config, out, sets=(), args=(), timeout: float | None = None, cwd=None) -> CliRun:
    """`taichi-sph --config CONFIG --out OUT --no-progress --quiet ARGS --set S ...`."""
    cmd = ["--config", config, "--out", out, "--no-progress", "--quiet", *args]
    for s in sets:
        cmd += ["--set", s]
    return run_cli(cmd, cwd=cwd, timeout=timeout)
