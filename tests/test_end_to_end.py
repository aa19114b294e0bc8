"""Whole runs through the command line: the run file layout of SPEC section 8, and a run that goes
unstable (exit code 3, one message naming step, quantity and particle, frames kept)."""

import json
import re
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
import yaml

from taichi_sph.io.hdf5 import RunFile

DIAGNOSTICS = ("time", "dt", "kinetic_energy", "max_speed", "water_volume", "cg_iterations", "cg_residual",
               "wall_seconds")
FRAME_UNITS = {"position": "m", "velocity": "m/s", "pressure": "Pa", "density": "kg/m^3"}
WATER, WALL = 0, 1


def test_hydrostatic_run_file_layout(run_cli, tmp_path):
    out = tmp_path / "h.h5"
    proc = run_cli("--config", "configs/hydrostatic.yaml", "--set", "dx=0.04", "--set", "end_time=0.1",
                   "--set", "output.every=0.05", "--out", out, "--no-progress", timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert out.is_file()

    with h5py.File(out, "r") as f:
        # root attributes
        a = f.attrs
        assert a["format"] == "taichi-sph"
        assert int(a["format_version"]) == 1
        assert a["mode"] == "isph"
        assert int(a["dim"]) == 2
        assert float(a["dx"]) == pytest.approx(0.04)
        for key in ("code_version", "arch"):
            assert isinstance(a[key], str) and a[key], key
        cfg = yaml.safe_load(a["config_yaml"])
        assert cfg["dx"] == pytest.approx(0.04)
        assert cfg["end_time"] == pytest.approx(0.1)
        assert cfg["output"]["every"] == pytest.approx(0.05)
        assert cfg["mode"] == "isph"
        tolerance = float(cfg["isph"]["ppe"]["tolerance"])
        dt = float(cfg["dt"])

        # particles
        kind = f["particles/kind"]
        assert kind.dtype == np.int8
        assert kind.ndim == 1
        n = kind.shape[0]
        kind = kind[()]
        assert set(np.unique(kind).tolist()) == {WATER, WALL}
        ids = f["particles/id"]
        assert ids.shape == (n,)
        assert len(np.unique(ids[()])) == n

        # frames
        times = f["frames/time"][()]
        assert times.shape == (3,)
        np.testing.assert_allclose(times, [0.0, 0.05, 0.1], rtol=0, atol=1e-9)
        n_frames = times.shape[0]
        expected_shapes = {"position": (n_frames, n, 2), "velocity": (n_frames, n, 2),
                           "pressure": (n_frames, n), "density": (n_frames, n), "active": (n_frames, n)}
        for name, shape in expected_shapes.items():
            ds = f[f"frames/{name}"]
            assert ds.shape == shape, name
            assert "units" in ds.attrs, name
            if name in FRAME_UNITS:
                assert ds.attrs["units"] == FRAME_UNITS[name], name
            if name != "active":
                assert np.all(np.isfinite(ds[()])), name
        assert f["frames/time"].attrs["units"] == "s"

        # per-step diagnostics
        n_steps = int(round(0.1 / dt))
        assert n_steps == 100
        for name in DIAGNOSTICS:
            ds = f[f"diagnostics/{name}"]
            assert ds.shape == (n_steps,), name
            assert "units" in ds.attrs, name
        diag = {name: f[f"diagnostics/{name}"][()] for name in DIAGNOSTICS}
    np.testing.assert_allclose(diag["dt"], dt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(diag["time"], dt * np.arange(1, n_steps + 1), rtol=0, atol=1e-9)
    assert np.all(diag["cg_iterations"] >= 1)
    assert np.all(diag["cg_residual"] <= tolerance), diag["cg_residual"].max()
    assert np.all(np.isfinite(diag["kinetic_energy"])) and np.all(diag["kinetic_energy"] >= 0)
    assert np.all(diag["max_speed"] >= 0)
    assert np.all(diag["water_volume"] > 0)
    assert np.all(diag["wall_seconds"] > 0)

    with RunFile(out) as rf:
        assert rf.n_frames == 3
        assert rf.units["active"]
        kind = rf.kind
        wall = kind == WALL
        first = rf.frame(0)
        for i in range(rf.n_frames):
            fr = rf.frame(i)
            assert fr["active"].dtype == np.bool_
            assert fr["active"].shape == (rf.n_particles,)
            assert fr["active"][wall].all()
            # walls do not move: positions equal bit for bit
            np.testing.assert_array_equal(fr["position"][wall], first["position"][wall])

    proc = run_cli("info", out, "--json", timeout=120)
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert info["n_frames"] == 3
    assert info["mode"] == "isph"
    assert info["format_version"] == 1
    # a tank at rest has no spray: no water particle without a water neighbour
    assert info["isolated_water"]["max"] == 0, info["isolated_water"]


def test_unstable_run_stops_with_exit_3_and_keeps_frames(run_cli, tmp_path):
    """The speed guard trips deterministically: a released column passes 0.5 m/s after ~0.03 s."""
    out = tmp_path / "u.h5"
    proc = run_cli("--config", "configs/dambreak.yaml", "--set", "dx=0.01", "--set", "end_time=0.5",
                   "--set", "output.every=0.02", "--set", "guard.max_speed=0.5", "--out", out, "--no-progress",
                   timeout=600)
    assert proc.returncode == 3, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    unstable = [line for line in proc.stderr.splitlines() if line.startswith("taichi-sph: unstable:")]
    assert len(unstable) == 1, proc.stderr
    message = unstable[0]
    assert "step" in message
    assert "speed" in message
    assert "particle id" in message
    m = re.search(r"step (\d+)", message)
    assert m, message
    step = int(m.group(1))
    m = re.search(r"particle id (\d+)", message)
    assert m, message
    pid = int(m.group(1))

    with RunFile(out) as rf:
        n_frames = rf.n_frames
        assert n_frames >= 2  # frame 0 and at least the state that tripped the guard
        times = rf.times
        assert times[0] == 0.0
        assert np.all(np.diff(times) > 0)
        assert times[-1] < 0.5
        for i in range(n_frames - 1):
            fr = rf.frame(i)
            for name in ("position", "velocity", "pressure", "density"):
                assert np.all(np.isfinite(fr[name])), (i, name)
        # the named particle exists and is the one moving faster than the guard in the last frame
        ids = rf.ids
        assert pid in ids.tolist()
        last = rf.frame(-1)
        row = int(np.flatnonzero(ids == pid)[0])
        speed = np.linalg.norm(last["velocity"], axis=1)
        assert speed[row] > 0.5
        assert speed[row] == np.nanmax(speed)
        diag = rf.diagnostics()
        assert diag["time"].shape == (step,)
        assert diag["max_speed"][-1] > 0.5
        assert np.all(diag["max_speed"][:-1] <= 0.5)
    # the XDMF sidecar is written whatever the end, naming every frame kept
    grids = ET.parse(out.with_suffix(".xdmf")).getroot().findall("Domain/Grid/Grid")
    assert len(grids) == n_frames


def test_fixed_dt_above_the_cfl_bound_is_reported(run_cli, tmp_path):
    """A fixed dt that lets the fastest particle cross more than `timestep.cfl` (0.2 in this config) of a
    spacing per step is what the adaptive step would have refused; the run reports its Courant number max speed x dt / dx
    (root attributes, and a warning naming the key where more than 1 % of the steps ran above it), so that
    a result that depends on dt is not silent. The isph dam break (a = 0.1 m, dx 1 cm) surges at up to
    ~2 sqrt(g a) ~ 2 m/s (Ritter's front speed): at dt 2 ms that is C ~ 0.4, at 0.25 ms C ~ 0.05."""
    base = ["--config", "configs/dambreak.yaml", "--set", "dx=0.01", "--set", "output.every=0.05", "--no-progress"]
    fast, slow = tmp_path / "fast.h5", tmp_path / "slow.h5"
    r = run_cli(*base, "--set", "dt=0.002", "--set", "end_time=0.2", "--out", fast)
    assert r.returncode == 0, r.stderr
    assert "timestep.cfl" in r.stderr and "ran above" in r.stderr, r.stderr
    r = run_cli(*base, "--set", "dt=0.00025", "--set", "end_time=0.1", "--out", slow)
    assert r.returncode == 0, r.stderr
    assert "ran above" not in r.stderr, r.stderr
    for path, dt in ((fast, 0.002), (slow, 0.00025)):
        with h5py.File(path, "r") as f:
            speed = f["diagnostics/max_speed"][:]
            c = float(f.attrs["courant_max"])
            assert c == pytest.approx(speed.max() * dt / 0.01, rel=1e-12)
            share = float(f.attrs["courant_above_cfl_share"])
            assert share == pytest.approx(np.mean(speed * dt / 0.01 > 0.2), abs=1e-12)
    with h5py.File(fast, "r") as f:
        assert 0.2 < float(f.attrs["courant_max"]) < 1.0 and float(f.attrs["courant_above_cfl_share"]) > 0.01
