"""Checkpoints, resume and kill-safety: a run stopped at half time and resumed equals the
uninterrupted run bit for bit (one CPU thread, both modes), whether it stopped at a periodic checkpoint
or at the checkpoint every finished run leaves at its end; SIGKILL leaves a readable run file with
every frame flushed before the kill, and the run resumes from its last checkpoint; SIGINT stops
after writing a checkpoint."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from taichi_sph.io.checkpoint import list_checkpoints
from taichi_sph.io.hdf5 import RunFile, RunFileError
from tests.conftest import cli_env

ROOT = Path(__file__).resolve().parents[1]
# one thread: the PPE's matrix is filled by a parallel kernel with atomic adds, whose order (and so the
# last bits of the sums) varies between threads; with one thread every step is the same arithmetic
TANK = ("--config", "configs/hydrostatic.yaml", "--set", "dx=0.04", "--set", "output.every=0.05", "--set", "threads=1",
        "--no-progress")


def _same_runs(a_path, b_path):
    with RunFile(a_path) as a, RunFile(b_path) as b:
        assert b.n_frames == a.n_frames
        np.testing.assert_array_equal(b.times, a.times)
        for i in range(a.n_frames):
            fa, fb = a.frame(i), b.frame(i)
            assert set(fa) == set(fb)
            for k in fa:
                np.testing.assert_array_equal(fb[k], fa[k], err_msg=f"frame {i} field {k}")
        da, db = a.diagnostics(), b.diagnostics()
        assert set(da) == set(db)
        for k in da:
            if k != "wall_seconds":
                np.testing.assert_array_equal(db[k], da[k], err_msg=f"diagnostic {k}")
        pa, pb = a.probes(), b.probes()
        assert set(pa) == set(pb)
        for k in pa:
            np.testing.assert_array_equal(pb[k][0], pa[k][0])
            np.testing.assert_array_equal(pb[k][1], pa[k][1])
        assert b.attrs["status"] == "completed"
        # the run's own summaries cover the whole run, not only the part after the checkpoint: the
        # Courant number of a fixed dt and the share of steps each dt limit bound (their counts go into
        # every checkpoint)
        for key in ("courant_max", "courant_max_time", "courant_above_cfl_share", "dt_limit_share"):
            assert (key in b.attrs) == (key in a.attrs), key
            if key in a.attrs:
                assert b.attrs[key] == a.attrs[key], key


@pytest.mark.parametrize("mode", ["isph", "wcsph_biot"])
def test_resume_equals_uninterrupted_run(run_cli, tmp_path, mode):
    probe = "probes=[{name: p, type: pressure, point: [0.2, 0.1], every: 0.02}]"
    args = (*TANK, "--set", f"mode={mode}", "--set", probe)
    full, half = tmp_path / "full.h5", tmp_path / "half.h5"
    proc = run_cli(*args, "--set", "end_time=0.2", "--out", full)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(*args, "--set", "end_time=0.1", "--set", "checkpoint.every=0.1", "--out", half)
    assert proc.returncode == 0, proc.stderr
    assert len(list_checkpoints(half)) == 1  # the one at t = 0.1 s, the run's end
    proc = run_cli("resume", half, "--set", "end_time=0.2", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    _same_runs(full, half)
    csv_full = full.with_suffix(".probes.csv").read_text()
    assert half.with_suffix(".probes.csv").read_text() == csv_full


@pytest.mark.parametrize("mode", ["isph", "wcsph_biot"])
def test_finished_run_resumes_without_checkpoint_every(run_cli, tmp_path, mode):
    """A run without `checkpoint.every` leaves one checkpoint at its end; `resume --set end_time=...`
    continues its frames to the later end time and gives one straight run to that time, bit for bit
    (one thread: the same arithmetic in the same order, see TANK)."""
    args = (*TANK, "--set", f"mode={mode}")
    full, half = tmp_path / "full.h5", tmp_path / "half.h5"
    proc = run_cli(*args, "--set", "end_time=0.2", "--out", full)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(*args, "--set", "end_time=0.1", "--out", half)
    assert proc.returncode == 0, proc.stderr
    found = list_checkpoints(half)
    assert len(found) == 1, found
    with RunFile(half) as rf:
        assert found[0].name == f"step_{int(rf.attrs['steps']):010d}.h5"  # the run's last step
        np.testing.assert_allclose(rf.times, 0.05 * np.arange(3), rtol=0, atol=1e-12)
    proc = run_cli("resume", half, "--set", "end_time=0.2", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    with RunFile(half) as rf:
        # the frames go on at output.every up to the new end time (times are sums of dt: round-off only)
        np.testing.assert_allclose(rf.times, 0.05 * np.arange(5), rtol=0, atol=1e-12)
        assert rf.diagnostics()["time"][-1] == pytest.approx(0.2, rel=1e-12)
    _same_runs(full, half)
    assert len(list_checkpoints(half)) == 2  # the first run's end and the resumed run's end (keep: 2)


def test_resume_keeps_the_precision_of_its_run_file(run_cli, tmp_path):
    """`precision: auto` resolves by mode (f32 in mode wcsph_biot); a run written when auto meant f64 (its
    config says auto, its file says f64) resumes in f64: the resumed run equals an uninterrupted f64 run
    bit for bit, which an f32 continuation could not."""
    import h5py

    args = (*TANK, "--set", "mode=wcsph_biot", "--set", "precision=f64")
    full, half = tmp_path / "full.h5", tmp_path / "half.h5"
    assert run_cli(*args, "--set", "end_time=0.2", "--out", full).returncode == 0
    assert run_cli(*args, "--set", "end_time=0.1", "--out", half).returncode == 0
    with h5py.File(half, "r+") as f:  # as written before auto depended on the mode
        text = f.attrs["config_yaml"]
        text = text.decode() if isinstance(text, bytes) else str(text)
        assert "precision: f64" in text
        f.attrs["config_yaml"] = text.replace("precision: f64", "precision: auto")
        assert f.attrs["precision"] in ("f64", b"f64")
    proc = run_cli("resume", half, "--set", "end_time=0.2", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    _same_runs(full, half)
    fresh = tmp_path / "fresh.h5"  # a new run of the same config resolves auto to f32
    proc = run_cli(*TANK, "--set", "mode=wcsph_biot", "--set", "end_time=0.02", "--out", fresh)
    assert proc.returncode == 0, proc.stderr
    with RunFile(fresh) as rf:
        assert rf.attrs["precision"] == "f32"


def _start(out, *extra):
    cmd = [sys.executable, "-m", "taichi_sph.cli", *TANK, "--out", str(out), *extra]
    return subprocess.Popen(cmd, cwd=ROOT, env=cli_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_frames(proc, out, n, timeout=120.0) -> int:
    """Poll the run file (opened read-only while it is written) until it holds n frames."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        assert proc.poll() is None, proc.communicate()[1]
        try:
            with RunFile(out) as rf:
                if rf.n_frames >= n:
                    return rf.n_frames
        except (RunFileError, OSError, KeyError):
            pass
        time.sleep(0.1)
    proc.kill()
    raise AssertionError(f"no {n} frames after {timeout} s")


def test_sigkill_leaves_readable_file_and_the_run_resumes(run_cli, tmp_path):
    out = tmp_path / "killed.h5"
    proc = _start(out, "--set", "end_time=3.0", "--set", "checkpoint.every=0.1")
    seen = _wait_for_frames(proc, out, 4)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    with RunFile(out) as rf:
        n = rf.n_frames
        assert n >= seen
        np.testing.assert_allclose(rf.times, 0.05 * np.arange(n), atol=1e-9)
        for i in range(n):
            assert np.all(np.isfinite(rf.field("position", i)))
        assert rf.attrs["status"] == "running"  # the kill left no chance to say more
    assert list_checkpoints(out), "a checkpoint every 0.1 s should exist after 4 frames"
    proc = run_cli("resume", out, "--set", "end_time=0.4", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    with RunFile(out) as rf:
        np.testing.assert_allclose(rf.times, 0.05 * np.arange(9), atol=1e-9)
        assert rf.diagnostics()["time"].shape == (400,)  # one row per step, none twice
        assert rf.attrs["status"] == "completed"


def test_sigint_stops_after_a_checkpoint(tmp_path):
    out = tmp_path / "interrupted.h5"
    proc = _start(out, "--set", "end_time=3.0")
    _wait_for_frames(proc, out, 2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    found = list_checkpoints(out)
    assert len(found) == 1, err
    with RunFile(out) as rf:
        assert rf.attrs["status"] == "interrupted"
        steps = int(rf.attrs["steps"])
    assert found[0].name == f"step_{steps:010d}.h5"


def test_resume_without_checkpoint_is_an_input_error(run_cli, tmp_path):
    out = tmp_path / "plain.h5"
    proc = run_cli(*TANK, "--set", "end_time=0.01", "--set", "output.every=0.01", "--out", out)
    assert proc.returncode == 0, proc.stderr
    for path in list_checkpoints(out):  # the one a finished run leaves at its end
        path.unlink()
    proc = run_cli("resume", out)
    assert proc.returncode == 2
    assert "no checkpoint to resume from" in proc.stderr and proc.stderr.count("\n") == 1
    proc = run_cli("resume", tmp_path / "missing.h5")
    assert proc.returncode == 2 and "missing.h5" in proc.stderr
