"""Shared test fixtures.

Taichi allows one live runtime per process: in-process tests share one CPU/f64 runtime for the
whole session (fixture `ti_cpu`); whole simulations run the CLI in a subprocess (`run_cli`).
"""

import functools
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _threads_per_worker() -> None:
    """Under pytest-xdist every worker's Taichi runtimes (this process's and each CLI subprocess's, which
    inherit the environment) take the worker's share of the cores, not all of them: N workers each
    running a runtime with a thread per core oversubscribe the machine, and a parallel loop then waits
    on threads the scheduler has parked (two of the suite's longest tests side by side on the 2-core AMD
    EPYC, warm cache: 66 s with two threads each, 62 s with one). Taichi reads TI_CPU_MAX_NUM_THREADS
    where ti.init is not given the count (a config's `threads`, a test's own ti.init, still decide for
    themselves)."""
    workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if workers:
        from taichi_sph.backend import cpu_threads_per_worker

        os.environ.setdefault("TI_CPU_MAX_NUM_THREADS", str(cpu_threads_per_worker(int(workers))))


_threads_per_worker()


@functools.lru_cache(maxsize=1)
def cuda_available() -> bool:
    """Whether Taichi starts on CUDA here (asked in a subprocess: this process's runtime is the CPU's).
    Without an NVIDIA driver (neither /dev/nvidiactl nor nvidia-smi) the answer is no at once."""
    import shutil

    if not (os.path.exists("/dev/nvidiactl") or shutil.which("nvidia-smi")):
        return False
    code = ("import taichi as ti; ti.init(arch=ti.cuda, log_level=ti.ERROR); "
            "raise SystemExit(0 if ti.lang.impl.current_cfg().arch == ti.cuda else 1)")
    try:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def pytest_collection_modifyitems(config, items):
    """Tests marked `long` run first (a stable sort: the order within each kind is kept), so that with `-n`
    the workers do not end with one of them running alone: the two longest sat near the end of the
    collection. Tests marked `cuda` are skipped where Taichi finds no CUDA GPU."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)
    marked = [item for item in items if item.get_closest_marker("cuda")]
    if marked and not cuda_available():
        skip = pytest.mark.skip(reason="no CUDA GPU found by Taichi")
        for item in marked:
            item.add_marker(skip)


def _init_cpu_runtime():
    """This process's Taichi runtime for in-process tests: CPU, f64."""
    import taichi as ti

    from taichi_sph import taichi_frontend
    from taichi_sph.backend import taichi_options

    taichi_frontend.install()
    ti.init(arch=ti.cpu, default_fp=ti.f64, random_seed=0, log_level=ti.WARN, **taichi_options())
    return ti


@pytest.fixture(scope="session")
def ti_cpu():
    yield _init_cpu_runtime()


#: a module starts on a fresh runtime where the shared one holds more SNode trees than this
FIELD_TREES_BEFORE_RESET = 128


@pytest.fixture(scope="module", autouse=True)
def _room_for_fields():
    """Each solver built in-process takes 2-17 of the runtime's 512 SNode trees for good (taichi_sph.backend,
    MAX_FIELD_TREES), and a worker that ran the in-process tests of several modules ran out: the next
    solver crashed it (tests/test_switches.py alone builds 56). Where the shared runtime holds more than
    FIELD_TREES_BEFORE_RESET, a module starts on a fresh one. At a module's start no Taichi object of
    another module is alive: module fixtures are torn down when the next test's module differs."""
    if "taichi" in sys.modules:
        from taichi_sph.backend import field_trees_used

        if (field_trees_used() or 0) > FIELD_TREES_BEFORE_RESET:
            import taichi as ti

            ti.reset()
            _init_cpu_runtime()
    yield


def _forked_commands() -> None:
    """The CLI runs of the tests (`cli`, and the tools and sweeps they call through
    taichi_sph.cli_process) are forked from a server that has imported Taichi and the package once
    (taichi_sph/cli_fork.py), not started as fresh interpreters: the suite starts about 300 of them,
    and each skips about half a second of imports (tests/test_cli_process.py checks that both ways
    write the same run). A run interrupted by a signal, the `schema` and `sweep` commands and
    rendering without a display start `python -m taichi_sph.cli` with subprocess themselves."""
    os.environ.setdefault("TAICHI_SPH_FORK", "1")


_forked_commands()


def cli_env():
    env = dict(os.environ)
    env.setdefault("TI_LOG_LEVEL", "warn")
    env["TAICHI_SPH_PROGRESS"] = "0"
    return env


def cli(*args, timeout=900, cwd=None):
    """Run `taichi-sph ARGS...` in a process of its own from the repository root (cli_process: forked
    from the test worker's server of imported modules); returns a CompletedProcess, stdout and stderr
    apart."""
    from taichi_sph.cli_process import run_cli_captured

    return run_cli_captured(args, env=cli_env(), cwd=cwd or ROOT, timeout=timeout)


@pytest.fixture
def run_cli():
    """`cli` as a fixture."""
    return cli


@pytest.fixture(scope="session")
def soil_column_run(tmp_path_factory):
    """configs/soil_column.yaml as shipped (saturated, k 1 mm/s, 0.2 s), run once per worker: the column at
    rest (tests/test_soil.py) and stage 1 of the two-stage column (tests/test_levee.py), both marked
    xdist_group("soil_column") so that one worker runs it. Returns (path, CompletedProcess)."""
    out = tmp_path_factory.mktemp("soil_column") / "s1.h5"
    return out, cli("--config", "configs/soil_column.yaml", "--out", out, "--no-progress")


def surge_front_series(path, a):
    """Dam break in a run file: T = t sqrt(2 g / a) and Z = z / a, z the surge front (the edge of the water
    body on the line of the first particle layer, `taichi_sph.probes.surge_front`)."""
    import numpy as np

    from taichi_sph.io.hdf5 import RunFile
    from taichi_sph.probes import surge_front

    with RunFile(path) as rf:
        dim, dx = rf.dim, rf.dx
        line = np.zeros(dim)
        line[-1] = 0.5 * dx
        if dim == 3:
            line[1] = float(rf.field("position", 0)[rf.kind == 0][:, 1].mean())  # mid-depth of a slice
        Z = []
        for i in range(rf.n_frames):
            arrays = {"position": rf.field("position", i), "kind": rf.kind, "active": rf.field("active", i),
                      "volume": np.full(len(rf.kind), dx**dim)}
            Z.append(surge_front(line, arrays, dx) / a)
        return rf.times * np.sqrt(2 * 9.81 / a), np.array(Z)


# The experiments' release delay in T = t sqrt(2 g / a): the time shift that best fits both Martin &
# Moyce series (and Koshizuka & Oka) over T in [1, 3] with the two solver modes at dx = a / 40, which
# agree with each other within 1.8 % there (best fits 0.265-0.29; docs/isph.md, "Dam-break front").
# The simulations release the column instantly; the experiments' fronts trail them by this constant
# delay, 10-15 ms at the experiments' scale.
RELEASE_DELAY_T = 0.27
MARTIN_MOYCE = ("martin_moyce_a1.125in_n2sq2", "martin_moyce_a2.25in_n2sq2")


def reference_front(name):
    """(T, Z) rows of a surge-front reference file in tests/data."""
    import numpy as np

    lines = (ROOT / "tests" / "data" / f"{name}.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines if ln.strip() and not ln.startswith("#") and not ln.startswith("T")]
    return np.array(rows, float)


def front_errors(T, Z, name, delay=0.0, lo=1.0, hi=3.0):
    """Reference T in [lo, hi] and the relative error of the simulated front there, the simulation's
    time axis moved later by `delay` (a release that starts `delay` after the experiment's t = 0)."""
    import numpy as np

    ref = reference_front(name)
    sel = (ref[:, 0] >= lo) & (ref[:, 0] <= hi)
    return ref[sel, 0], np.interp(ref[sel, 0] - delay, T, Z) / ref[sel, 1] - 1


def check_fronts_against_martin_moyce(T, Z, early: float, late: float, shifted: float) -> None:
    """Both Martin & Moyce series over T in [1, 3]: the simulated front leads the raw data everywhere, by
    less than `early` for T < 1.5 and `late` after, and with the release delay taken out it is within
    `shifted` of the data (relative errors)."""
    import numpy as np

    for name in MARTIN_MOYCE:
        Tr, err = front_errors(T, Z, name)
        first = Tr < 1.5
        assert np.all(err > 0.0), (name, err)
        assert np.all(err[first] < early), (name, err)
        assert np.all(err[~first] < late), (name, err)
        _, err = front_errors(T, Z, name, delay=RELEASE_DELAY_T)
        assert np.all(np.abs(err) < shifted), (name, err)
