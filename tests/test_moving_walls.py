"""Obstacles with a prescribed motion (`obstacles[k].motion`, taichi_sph/sph/wall_motion.py): Stokes'
first problem (constant velocity) and second problem (oscillation) in both modes against their exact
solutions, the obstacle's own kinematics, and a resumed run that equals the uninterrupted one."""

from math import erfc

import numpy as np
import pytest

from taichi_sph.io.hdf5 import RunFile

from .test_checkpoint import _same_runs

CONFIG = "configs/stokes_plate.yaml"
U, NU, FACE, PERIOD = 0.05, 1.0e-3, 0.003, 0.01  # plate speed, viscosity, plate face height, period (the config)


@pytest.mark.parametrize("mode", ["isph", "wcsph_biot"])
def test_stokes_first_problem(run_cli, tmp_path, mode):
    """A plate starts to slide along its face at U under water at rest (no-slip, no gravity, periodic
    along the plate): u(y, t) = U erfc(y / (2 sqrt(nu t))). Measured at dx 1 mm over the five frames to
    0.05 s (the layer reaches 14 mm): rms error 0.0007-0.0021 U (isph), 0.0011-0.0028 U (wcsph_biot);
    largest single-particle error 0.0049 U / 0.0076 U. Bounds: rms 0.01 U and any particle 0.02 U, about
    four and three times the largest measured; a wall that ignored its motion leaves the water at rest, rms
    error ~0.4 U, and a slip plate drags nothing. The plate's particles must sit where the motion puts
    them (x0 + U t, wrapped by the period) and carry its velocity."""
    out = tmp_path / "plate.h5"
    extra = ["--variant", "wcsph"] if mode == "wcsph_biot" else []
    r = run_cli("--config", CONFIG, *extra, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        assert rf.mode == mode
        water, wall = rf.kind == 0, rf.kind == 1
        x0 = rf.field("position", 0)
        plate = wall & (x0[:, 1] > 0.0)  # the tank floor lies below y = 0
        assert plate.sum() == 30
        for i in range(1, rf.n_frames):
            f, t = rf.frame(i), float(rf.times[i])
            y = f["position"][water][:, 1] - FACE
            u = f["velocity"][water][:, 0]
            exact = np.array([U * erfc(v / (2.0 * np.sqrt(NU * t))) for v in y])
            assert np.sqrt(np.mean((u - exact) ** 2)) < 0.01 * U, (t, np.sqrt(np.mean((u - exact) ** 2)) / U)
            assert np.abs(u - exact).max() < 0.02 * U, t
            moved = f["position"][plate][:, 0] - x0[plate][:, 0] - U * t
            moved -= PERIOD * np.round(moved / PERIOD)
            assert np.abs(moved).max() < 1e-9
            assert np.allclose(f["velocity"][plate], [U, 0.0])
            assert np.allclose(f["position"][wall & ~plate], x0[wall & ~plate])


def _oscillating_plate_exact(y, t, period, n=4000):
    """Fluid at rest above a plate whose velocity is U cos(2 pi t / period) from t = 0 (Stokes' second
    problem with its start-up), by Duhamel's integral over the first problem's erfc response:
    u = U erfc(y / (2 sqrt(nu t))) + int_0^t u_w'(s) erfc(y / (2 sqrt(nu (t - s)))) ds."""
    from scipy.special import erfc as erfc_v

    w = 2.0 * np.pi / period
    s = np.linspace(0.0, t, n)
    tau = np.maximum(t - s, 1e-300)[None, :]
    integrand = -U * w * np.sin(w * s)[None, :] * erfc_v(np.asarray(y)[:, None] / (2.0 * np.sqrt(NU * tau)))
    trapezoid = getattr(np, "trapezoid", None) or np.trapz  # numpy < 2 names it trapz
    return U * erfc_v(np.asarray(y) / (2.0 * np.sqrt(NU * t))) + trapezoid(integrand, s, axis=1)


@pytest.mark.parametrize("variant, rms_bound, max_bound", [("oscillating", 0.005, 0.025),
                                                       ("oscillating_wcsph", 0.012, 0.05)])
def test_stokes_second_problem(run_cli, tmp_path, variant, rms_bound, max_bound):
    """The plate oscillates along its face, x = A sin(2 pi t / T) with A = U T / (2 pi) (U 0.05 m/s,
    T 0.05 s, layer sqrt(2 nu / omega) = 4 mm = 4 dx), from rest at t = 0, for two periods. Against the
    exact start-up solution (Duhamel's integral), measured over the 20 frames: worst rms error 0.0019 U
    (isph) and 0.0049 U (wcsph_biot), largest single-particle error 0.011 U / 0.021 U. Bounds, each mode
    its own, about two and a half times its measured: rms 0.005 U / 0.012 U, any particle 0.025 U /
    0.05 U; a plate moving a quarter period out of phase leaves an rms error near 0.3 U. The plate's
    particles follow x0 + A sin(2 pi t / T) to rounding."""
    out = tmp_path / "osc.h5"
    r = run_cli("--config", CONFIG, "--variant", variant, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    period = 0.05
    amp = U * period / (2.0 * np.pi)
    with RunFile(out) as rf:
        water, wall = rf.kind == 0, rf.kind == 1
        x0 = rf.field("position", 0)
        plate = wall & (x0[:, 1] > 0.0)
        assert rf.n_frames == 21
        for i in range(1, rf.n_frames):
            f, t = rf.frame(i), float(rf.times[i])
            y = f["position"][water][:, 1] - FACE
            err = f["velocity"][water][:, 0] - _oscillating_plate_exact(y, t, period)
            assert np.sqrt(np.mean(err**2)) < rms_bound * U, (t, np.sqrt(np.mean(err**2)) / U)
            assert np.abs(err).max() < max_bound * U, (t, np.abs(err).max() / U)
            moved = f["position"][plate][:, 0] - x0[plate][:, 0] - amp * np.sin(2.0 * np.pi * t / period)
            moved -= PERIOD * np.round(moved / PERIOD)
            assert np.abs(moved).max() < 1e-9


@pytest.mark.parametrize("mode", ["isph", "wcsph_biot"])
def test_resume_with_a_moving_plate(run_cli, tmp_path, mode):
    """Stopped at half time and resumed, the run equals the uninterrupted one bit for bit (one thread):
    the plate's place and velocity come back from the checkpoint, and the guard expects it there."""
    args = ["--config", CONFIG, "--set", "threads=1", "--set", "output.every=0.005", "--no-progress"]
    if mode == "wcsph_biot":
        args += ["--variant", "wcsph"]
    full, half = tmp_path / "full.h5", tmp_path / "half.h5"
    assert run_cli(*args, "--set", "end_time=0.02", "--out", full).returncode == 0
    r = run_cli(*args, "--set", "end_time=0.01", "--set", "checkpoint.every=0.01", "--out", half)
    assert r.returncode == 0, r.stderr
    r = run_cli("resume", half, "--set", "end_time=0.02", "--no-progress")
    assert r.returncode == 0, r.stderr
    _same_runs(full, half)


def test_ramped_velocity_reaches_its_distance_with_bounded_acceleration():
    """`motion.ramp`: the speed follows a half cosine up after start and down before stop. References: the
    distance is V (stop - start - ramp) (the two half-cosine ramps each cover half the distance at full
    speed) and the largest acceleration pi V / (2 ramp); the speed never exceeds V."""
    from taichi_sph.sph.wall_motion import Motion

    v, ramp = 0.1, 1.0
    m = Motion(0.5, 6.5, velocity=np.array([v, 0.0]), ramp=ramp)
    t = np.linspace(0.0, 7.0, 70001)
    d = np.array([m.displacement(s)[0] for s in t])
    speed = np.gradient(d, t)
    accel = np.gradient(speed, t)
    assert d[-1] == pytest.approx(v * (6.0 - ramp), rel=1e-12)
    assert speed.max() <= v * (1 + 1e-9) and speed[t < 0.5].max() == 0.0
    # finite differences on a 0.1 ms grid resolve the cosine's peak to 1e-6 relative
    assert np.abs(accel).max() == pytest.approx(np.pi * v / (2 * ramp), rel=1e-4)
    # without a stop the body keeps its full speed after the ramp
    m = Motion(0.0, np.inf, velocity=np.array([v, 0.0]), ramp=ramp)
    assert m.displacement(3.0)[0] == pytest.approx(v * (3.0 - ramp / 2), rel=1e-12)
