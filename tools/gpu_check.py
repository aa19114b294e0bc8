"""All the CUDA checks in one command, each within a time budget, one check on the GPU at a time.

In order: Taichi starts on CUDA; the tests marked `cuda`; CPU/CUDA parity (tools/parity.py); every config
with `--arch cuda` (tools/config_matrix.py); the PPE iteration's bandwidth, both reductions in f64
(tools/bench_ppe_bandwidth.py); the seed's free fall timed alone; the step benchmark on CUDA
(tools/bench.py, merged into a copy of docs/performance.md); the offloaded tasks that take a step's
device time (`profile`: tools/bench.py --kernel-profile). A check that overruns its budget is stopped
(its process group killed) and the next one starts; each writes its log and report into OUT.

    python tools/gpu_check.py --out DIR [--only tests parity configs bandwidth freefall bench bench3d]
        [--budget freefall=90 ...] [--scale 1.0] [--arch cpu]

`--only` runs those checks in the order given (after `start`), so that the ones that matter most come
first when device time is short. With about 15 minutes of GPU time (the machine's start included, 1-2
minutes), one call of about 10 minutes; the fourth round (docs/performance.md) ran the tests (57 s),
the parity (112 s), the configs (24 of 31 in 170 s) and the 3D step (89 s), so next: the parity and the
configs again after the isph changes of that round, then the free fall timed alone

    python tools/gpu_check.py --out DIR --only parity configs freefall \
        --budget parity=130 configs=300 freefall=100

(at most 530 s of checks, under ten minutes)

`--budget NAME=SECONDS` sets one check's budget; `--scale` multiplies every budget. The tests and the
parity cases run four processes at once (each a CPU and a GPU run), the other checks one. `--arch cpu` runs the same sequence on the CPU (a dry run of the
tool itself: the `cuda` tests skip, parity compares the CPU with itself). Prints one line per check (exit status, seconds) and writes
DIR/summary.txt. Exits 1 when a check fails or overruns.
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable

#: name -> (budget in seconds, command (OUT is replaced by the output folder))
CHECKS = {
    "start": (60, [PY, "-c", ("import taichi as ti; ti.init(arch=ti.cuda); "
                              "assert ti.lang.impl.current_cfg().arch == ti.cuda; print('cuda ok')")]),
    # four at a time: the tests and the parity cases each run a CPU and a GPU process, and the host has cores
    # to spare (on an H100 host of 16 cores: the 7 tests in 84 s with four workers; one at a time they did
    # not finish in 230 s)
    "tests": (240, [PY, "-m", "pytest", "-q", "-m", "cuda", "tests/test_cuda.py", "-p", "no:cacheprovider",
                    "-n", "4"]),
    "parity": (240, [PY, "tools/parity.py", "--against", "cuda", "--jobs", "4", "--out-dir", "OUT/parity",
                     "--json", "OUT/parity.json"]),
    "configs": (420, [PY, "tools/config_matrix.py", "--arch", "cuda", "--timeout", "120", "--jobs", "4", "--out-dir", "OUT/configs",
                      "--json", "OUT/configs.json", "--report", "OUT/performance.md"]),
    "bandwidth": (120, [PY, "tools/bench_ppe_bandwidth.py", "--arch", "cuda", "--sizes", "2d1m", "2d4m", "3d1m", "--iterations", "100",
                        "--reductions", "atomic", "two_stage", "--json", "OUT/bandwidth.json"]),
    "freefall": (120, [PY, "-m", "taichi_sph.cli", "--config", "configs/freefall.yaml", "--arch", "cuda",
                       "--out", "OUT/freefall.h5", "-q"]),
    # tools/bench.py writes its table when all its cases are done: two calls, so that an overrun loses one
    "bench": (240, [PY, "tools/bench.py", "--arch", "cuda", "--modes", "wcsph", "isph_free", "--dims", "2",
                    "--sizes", "S", "L", "XL", "--min-time", "2", "--no-jit", "--out", "OUT/performance.md", "--keep"]),
    # where a step's device time goes: the offloaded tasks that take most of it (Taichi's kernel profiler)
    "profile": (150, [PY, "tools/bench.py", "--arch", "cuda", "--modes", "wcsph", "isph_free", "--dims", "2",
                      "--sizes", "S", "L", "--min-time", "1", "--no-jit", "--kernel-profile", "12",
                      "--out", "OUT/profile.md"]),
    "bench3d": (180, [PY, "tools/bench.py", "--arch", "cuda", "--modes", "isph_porous", "wcsph", "--dims", "3",
                      "--sizes", "S", "L", "--min-time", "2", "--no-jit", "--out", "OUT/performance.md", "--keep"]),
}


def run_check(name: str, budget: float, cmd: list, out: Path, arch: str = "cuda") -> tuple[int, float]:
    cmd = [str(out) + c[3:] if c.startswith("OUT") else c for c in cmd]
    if arch != "cuda":
        cmd = [c.replace("ti.cuda", f"ti.{arch}") for c in cmd]
        cmd = [arch if c == "cuda" and k > 0 and cmd[k - 1] in ("--arch", "--against") else c
               for k, c in enumerate(cmd)]
    env = dict(os.environ, TAICHI_SPH_PROGRESS="0", TI_LOG_LEVEL="warn", PYTHONUNBUFFERED="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    t0 = time.perf_counter()
    with open(out / f"{name}.log", "w") as log:
        # a process group of its own, so that an overrun kills the check's children too
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            rc = proc.wait(timeout=budget)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            rc = 124
    return rc, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--only", nargs="+", choices=list(CHECKS), help="these checks, in this order ('start' first)")
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies every budget")
    ap.add_argument("--budget", nargs="+", default=[], metavar="NAME=SECONDS",
                    help="a check's own budget in seconds (before --scale), e.g. freefall=90")
    ap.add_argument("--arch", default="cuda", choices=["cuda", "cpu"], help="cpu: a dry run of the tool")
    args = ap.parse_args(argv)
    budgets = {name: budget for name, (budget, _) in CHECKS.items()}
    for item in args.budget:
        name, _, seconds = item.partition("=")
        if name not in CHECKS:
            ap.error(f"--budget {item}: no check named {name!r}")
        try:
            budgets[name] = float(seconds)
        except ValueError:
            ap.error(f"--budget {item}: seconds must be a number")
    args.out.mkdir(parents=True, exist_ok=True)
    perf = args.out / "performance.md"
    if not perf.exists():  # the bench and config tables merge into a copy of the project's report
        for suffix in (".md", ".json"):
            src = ROOT / "docs" / f"performance{suffix}"
            if src.exists():
                shutil.copy(src, args.out / f"performance{suffix}")
    lines, failed = [], 0
    # the order of --only, so that the checks that matter most run first when device time is short
    names = ["start"] + [n for n in args.only if n != "start"] if args.only else list(CHECKS)
    for name in names:
        budget, cmd = budgets[name], CHECKS[name][1]
        rc, seconds = run_check(name, budget * args.scale, cmd, args.out, args.arch)
        line = f"{name:10s} exit {rc:3d}  {seconds:6.1f} s  (budget {budget * args.scale:.0f} s)"
        print(line, flush=True)
        lines.append(line)
        failed += rc != 0
        if name == "start" and rc != 0:
            break
    (args.out / "summary.txt").write_text("\n".join(lines) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
