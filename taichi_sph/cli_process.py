"""One `taichi-sph` command in a process of its own (Taichi's state is per process), as `taichi-sph
sweep` runs its cases and tools/validate.py and tools/stress.py run theirs: the exit code, the output,
the one-line message that explains a failure, and the wall time of the process."""

from __future__ import annotations

import subprocess
import sys
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


def run_cli(args, *, log_path: str | Path | None = None, env: dict | None = None, cwd: str | Path | None = None,
            timeout: float | None = None) -> CliRun:
    """`python -m taichi_sph.cli ARGS...`; the output goes to `log_path` (and is read back from it) or
    is captured."""
    cmd = [sys.executable, "-m", "taichi_sph.cli", *map(str, args)]
    t0 = time.perf_counter()
    try:
        if log_path is not None:
            with open(log_path, "w", encoding="utf-8") as logf:
                proc = subprocess.run(cmd, stdout=logf, stderr=subprocess.STDOUT, env=env, cwd=cwd, timeout=timeout,
                                      check=False)
            output = Path(log_path).read_text(encoding="utf-8", errors="replace")
        else:
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd, timeout=timeout, check=False)
            output = proc.stdout + proc.stderr
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        rc, output = -1, f"{PREFIX}timed out after {timeout:g} s"
        if log_path is not None:
            with open(log_path, "a", encoding="utf-8") as logf:
                logf.write(output + "\n")
    return CliRun(rc, output, time.perf_counter() - t0)


def run_case_cli(config, out, sets=(), args=(), timeout: float | None = None, cwd=None) -> CliRun:
    """`taichi-sph --config CONFIG --out OUT --no-progress --quiet ARGS --set S ...`."""
    cmd = ["--config", config, "--out", out, "--no-progress", "--quiet", *args]
    for s in sets:
        cmd += ["--set", s]
    return run_cli(cmd, cwd=cwd, timeout=timeout)
