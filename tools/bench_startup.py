"""Start-up of a `taichi-sph` command: a fresh `python -m taichi_sph.cli` against one forked from the
server of imported modules (taichi_sph/cli_fork.py, TAICHI_SPH_FORK=1), both through
taichi_sph.cli_process as the tests, sweeps and tools/validate.py start their commands.

Each round runs every case once each way, the two ways alternating (their order swapped every round),
so that the machine's load hits both alike. The cases are short runs whose time is mostly start-up:
imports, Taichi's runtime, its front end and the loading of kernels from the offline cache (warmed by
a first, untimed run of each case), a few steps, the run file. Reports the median wall time per command
of each way over the rounds, and their ratio.

    python tools/bench_startup.py [--rounds 7] [--threads 1] [--out docs/performance.md]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench import machine
from bench_wcsph import load_average, replace_section

from taichi_sph.cli_process import run_cli

#: (name, arguments): a few steps of each mode, and a bad config (the error path, no Taichi runtime)
CASES = (
    ("hydrostatic (isph, 2 steps)", ["--config", "configs/hydrostatic.yaml", "--set", "end_time=0.002"]),
    ("consolidation (wcsph_biot, soil)", ["--config", "configs/consolidation.yaml", "--set", "end_time=0.0005"]),
    ("bad config (exit 2)", ["--config", "configs/hydrostatic.yaml", "--set", "dx=-1"]),
)


def _once(args, out: Path, forked: bool) -> float:
    os.environ["TAICHI_SPH_FORK"] = "1" if forked else "0"
    t0 = time.perf_counter()
    res = run_cli([*args, "--out", str(out), "--no-progress"], cwd=ROOT)
    seconds = time.perf_counter() - t0
    if res.rc not in (0, 2):
        raise SystemExit(f"bench_startup: {' '.join(args)} failed ({res.rc}): {res.failure_line()}")
    return seconds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--threads", type=int, default=1, help="TI_CPU_MAX_NUM_THREADS of the commands")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance.md"))
    ap.add_argument("--section", default="startup")
    a = ap.parse_args()
    os.environ["TI_CPU_MAX_NUM_THREADS"] = str(a.threads)
    os.environ["TAICHI_SPH_PROGRESS"] = "0"
    times = {name: {True: [], False: []} for name, _ in CASES}
    load0 = load_average()
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        out = Path(tmp) / "run.h5"
        for _, args in CASES:  # warm the offline cache and the fork server
            _once(args, out, True)
        for r in range(a.rounds):
            for name, args in CASES:
                for forked in ((True, False) if r % 2 else (False, True)):
                    times[name][forked].append(_once(args, out, forked))
            print(f"round {r + 1}: " + ", ".join(
                f"{name} {times[name][False][-1]:.2f} / {times[name][True][-1]:.2f} s" for name, _ in CASES))
    load1 = load_average()
    lines = [
        (f"Machine: {machine()}; {a.threads} Taichi thread(s) per command. Produced by `python "
        f"tools/bench_startup.py` on {date.today().isoformat()}: {a.rounds} rounds, each case once each way per "
        f"round, alternating; load {load0:.1f} / {load1:.1f} (1-minute load average at the start / end). Wall "
        f"seconds per command, median (range over the rounds)."),
        "",
        "| command | fresh process | forked from the server | fresh / forked |",
        "|---|---|---|---|",
    ]
    for name, _ in CASES:
        fresh, forked = times[name][False], times[name][True]
        mf, mk = statistics.median(fresh), statistics.median(forked)
        lines.append(f"| {name} | {mf:.2f} ({min(fresh):.2f}-{max(fresh):.2f}) | {mk:.2f} ({min(forked):.2f}-"
                     f"{max(forked):.2f}) | {mf / mk:.2f} |")
    text = "\n".join(lines)
    print(text)
    replace_section(Path(a.out), a.section, text)
    print(f"wrote section {a.section} of {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
