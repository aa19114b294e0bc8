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
