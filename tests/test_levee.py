"""Mode wcsph_biot, levees (seed 002 sections 3.4-3.5): two-stage runs (a geostatic stage seeds the next),
the river inflow, steady seepage through a rigid levee against Dupuit, and where a saturated embankment
first yields."""

import numpy as np

from taichi_sph.io.hdf5 import RunFile

G = 9.81
N0, RHO_S, RHO_W = 0.4, 2650.0, 1000.0
WATER, SOIL = 0, 2


def _soil_frame(path, k):
    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        f = rf.frame(k)
        return f["position"][soil], f["effective_stress"][soil], f["plastic_strain"][soil], rf.dx


def test_two_stage_column(run_cli, tmp_path):
    """configs/soil_column.yaml (saturated, 0.30 m): stage 1 the geostatic stage (K0 start, damping
    20 1/s, 0.2 s), stage 2 starts from its last frame (`wcsph.soil.start_from`) without damping for
    0.1 s. Stage 2's start must carry stage 1's end state exactly (positions, stress, plastic strain), with
    sigma'_v within 5 % of (gamma_sat - gamma_w) z (the acceptance number; measured mean 1.004, range
    0.999-1.015 below 0.1 m depth, the top rows carry a kernel-truncation error), and the undamped second
    stage must settle less than 0.5 % of H (measured 8e-7 H)."""
    s1, s2 = tmp_path / "s1.h5", tmp_path / "s2.h5"
    r = run_cli("--config", "configs/soil_column.yaml", "--out", s1, "--no-progress")
    assert r.returncode == 0, r.stderr
    r = run_cli("--config", "configs/soil_column.yaml", "--set", f"wcsph.soil.start_from.run={s1}",
                "--set", "wcsph.soil.damping=0", "--set", "end_time=0.1", "--out", s2, "--no-progress")
    assert r.returncode == 0, r.stderr
    x1, sig1, ep1, _dx = _soil_frame(s1, -1)
    x2, sig2, ep2, _ = _soil_frame(s2, 0)
    # carried over as stored (the run file holds what the solver had)
    assert np.array_equal(x1, x2) and np.array_equal(sig1, sig2) and np.array_equal(ep1, ep2)
    H = 0.3
    with RunFile(s1) as rf:
        y0 = rf.field("position", 0)[rf.kind == SOIL][:, 1]
    depth = H - y0
    deep = depth > 0.1
    ratio = sig2[deep, 1, 1] / ((1 - N0) * (RHO_S - RHO_W) * G * depth[deep])
    assert abs(ratio.mean() - 1) < 0.05 and np.abs(ratio - 1).max() < 0.1, (ratio.mean(), ratio.min(), ratio.max())
    x_end, *_ = _soil_frame(s2, -1)
    assert np.abs(x2[:, 1] - x_end[:, 1]).max() / H < 0.005
    assert np.abs(y0 - x_end[:, 1]).max() / H < 0.005  # and over both stages


def test_start_from_errors(run_cli, tmp_path):
    """A missing run file, or one whose soil is not this config's soil: one line naming the key, exit 2,
    no run file written."""
    out = tmp_path / "x.h5"
    r = run_cli("--config", "configs/soil_column.yaml", "--set", f"wcsph.soil.start_from.run={tmp_path}/none.h5",
                "--out", out, "--no-progress")
    assert r.returncode == 2 and "wcsph.soil.start_from.run" in r.stderr and "none.h5" in r.stderr, r.stderr
    assert not out.exists()
    s1 = tmp_path / "s1.h5"
    r = run_cli("--config", "configs/soil_column.yaml", "--set", "end_time=0.005", "--out", s1, "--no-progress")
    assert r.returncode == 0, r.stderr
    r = run_cli("--config", "configs/soil_column.yaml", "--set", f"wcsph.soil.start_from.run={s1}",
                "--set", "soil_blocks[0].max=[0.1,0.2]", "--out", out, "--no-progress")
    assert r.returncode == 2 and "wcsph.soil.start_from.run" in r.stderr and "same soil" in r.stderr, r.stderr
    assert len([ln for ln in r.stderr.splitlines() if "error" in ln]) == 1, r.stderr
    assert not out.exists()
