"""A command forked from the server of imported modules (taichi_sph/cli_fork.py, TAICHI_SPH_FORK=1, which
the test suite's runs take) against the same command as a fresh `python -m taichi_sph.cli`: the run files
bit for bit, the offline cache written, the exit code and message of bad input, a time-out, a working
directory that does not exist."""

import subprocess

import h5py
import numpy as np
import pytest

from taichi_sph.cli_process import run_cli, run_cli_captured

from .conftest import ROOT, cli_env

CASES = {
    # f64 on the CPU: a diagnostic returned through f32 shows here (isph's _k_diagnostics did, where its
    # module was imported before ti.init, as in a forked command)
    "isph": ["--config", "configs/hydrostatic.yaml", "--set", "end_time=0.01", "--set", "output.every=0.005"],
    "wcsph_biot": ["--config", "configs/consolidation.yaml", "--set", "end_time=0.002",
                   "--set", "output.every=0.001"],
}


def _contents(path):
    """Every dataset of a run file's frames and diagnostics (not the wall-clock times)."""
    out = {}
    with h5py.File(path, "r") as f:
        for group in ("frames", "diagnostics"):
            for name, data in f[group].items():
                if name != "wall_seconds":
                    out[f"{group}/{name}"] = data[()]
    return out


@pytest.mark.parametrize("mode", sorted(CASES))
def test_forked_and_fresh_commands_write_the_same_run(tmp_path, monkeypatch, mode):
    env = dict(cli_env(), TI_CPU_MAX_NUM_THREADS="1")
    cache = tmp_path / "cache"
    if mode == "isph":  # an empty offline cache (compiling the small case's kernels takes a few seconds)
        env["TAICHI_SPH_CACHE"] = str(cache)
    runs = {}
    for fork in ("1", "0"):  # the forked one first
        monkeypatch.setenv("TAICHI_SPH_FORK", fork)
        out = tmp_path / f"fork{fork}.h5"
        r = run_cli_captured([*CASES[mode], "--out", out, "--no-progress"], env=env, cwd=ROOT, timeout=600)
        assert r.returncode == 0, r.stderr
        if fork == "1" and mode == "isph":
            # the child reset Taichi before it left, which writes what it compiled to the cache
            assert any(cache.rglob("*.tic")), sorted(cache.rglob("*"))
        runs[fork] = _contents(out)
    assert runs["1"].keys() == runs["0"].keys()
    differ = [k for k in runs["0"] if not np.array_equal(runs["0"][k], runs["1"][k], equal_nan=True)]
    assert not differ, differ


@pytest.mark.parametrize("fork", ["1", "0"])
def test_bad_input_and_time_out_alike_forked_or_fresh(tmp_path, monkeypatch, fork):
    monkeypatch.setenv("TAICHI_SPH_FORK", fork)
    out = tmp_path / "bad.h5"
    r = run_cli_captured(["--config", "configs/hydrostatic.yaml", "--set", "dx=-1", "--out", out], env=cli_env(),
                         cwd=ROOT, timeout=120)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("taichi-sph: error:") and "dx" in lines[0], r.stderr
    assert not out.exists()
    # a run past its time-out is killed: run_cli says so in its output, run_cli_captured raises
    long_run = ["--config", "configs/hydrostatic.yaml", "--set", "end_time=100", "--out", tmp_path / "long.h5",
                "--no-progress"]
    res = run_cli(long_run, env=cli_env(), cwd=ROOT, timeout=2)
    assert res.rc == -1 and res.failure_line() == "taichi-sph: timed out after 2 s", res.output[-300:]
    with pytest.raises(subprocess.TimeoutExpired):
        run_cli_captured(long_run, env=cli_env(), cwd=ROOT, timeout=2)
    # a working directory that does not exist: the same error before anything starts, forked or fresh
    with pytest.raises(FileNotFoundError, match="no such directory"):
        run_cli_captured(["--config", "configs/hydrostatic.yaml"], env=cli_env(), cwd=tmp_path / "absent")
