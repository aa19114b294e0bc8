"""Shared test fixtures.

Taichi allows one live runtime per process: in-process tests share one CPU/f64 runtime for the
whole session (fixture `ti_cpu`); whole simulations run the CLI in a subprocess (`run_cli`).
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def ti_cpu():
    import taichi as ti

    ti.init(arch=ti.cpu, default_fp=ti.f64, random_seed=0, log_level=ti.WARN)
    yield ti


def cli_env():
    env = dict(os.environ)
    env.setdefault("TI_LOG_LEVEL", "warn")
    env["TAICHI_SPH_PROGRESS"] = "0"
    return env


@pytest.fixture
def run_cli():
    """Run `taichi-sph ARGS...` in a subprocess from the repository root; returns CompletedProcess."""

    def _run(*args, timeout=900, cwd=None):
        cmd = [sys.executable, "-m", "taichi_sph.cli", *map(str, args)]
        return subprocess.run(cmd, cwd=cwd or ROOT, env=cli_env(), capture_output=True, text=True, timeout=timeout)

    return _run


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
