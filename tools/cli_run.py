"""One simulation through the command line, as the validation suite and the stress matrix run it: a
process of its own (Taichi's state is per process), quiet, with a time limit; the exit code, the last
`taichi-sph:` line of its error output (the guard's or the input check's one-line message) and the wall
time of the process."""

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class CliRun:
    rc: int  # exit code; -1 when the time limit stopped it
    message: str  # the last "taichi-sph: " line without its prefix (or the tail of stderr), "" if none
    seconds: float  # wall time of the process


def run_cli(config: str, out: Path, sets=(), args=(), timeout: float = 3600.0) -> CliRun:
    """`python -m taichi_sph.cli --config CONFIG --out OUT --no-progress --quiet ARGS --set S ...` from the
    repository root."""
    cmd = [sys.executable, "-m", "taichi_sph.cli", "--config", config, "--out", str(out), "--no-progress",
           "--quiet", *args]
    for s in sets:
        cmd += ["--set", s]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False)
        rc, err = proc.returncode, proc.stderr
    except subprocess.TimeoutExpired:
        rc, err = -1, f"taichi-sph: timed out after {timeout:g} s"
    lines = [ln.removeprefix("taichi-sph: ") for ln in err.splitlines() if ln.startswith("taichi-sph: ")]
    message = lines[-1] if lines else err.strip()[-300:]
    return CliRun(rc, message, time.perf_counter() - t0)
