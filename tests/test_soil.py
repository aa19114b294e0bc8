"""Mode wcsph_biot, soil and Biot coupling (seed 002 sections 2.4 (2), 2.5, 3.3): soil columns at rest
(dry and saturated) against the geostatic stresses, the yield surface against Mohr-Coulomb (element test,
infinite slope), the friction keys, and the dry column collapse (final slope, run-out, two resolutions)."""

import math

import numpy as np
import pytest
import taichi as ti

from taichi_sph.config.load import load_config
from taichi_sph.errors import InputError
from taichi_sph.io.hdf5 import RunFile
from taichi_sph.wcsph import soil
from taichi_sph.wcsph.consolidation import (
    consolidation_coefficient,
    constrained_modulus,
    isochrone_errors,
)

G = 9.81
N0, RHO_S, RHO_W = 0.4, 2650.0, 1000.0
WATER, SOIL = 0, 2


def _column(path):
    """Largest settlement / H and the mean and extreme ratio of sigma'_v to its expected value at depths
    below 0.1 m (the top rows carry a few hundred Pa and a kernel-truncation error there), last frame."""
    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        sat = (rf.kind == WATER).any()
        x0 = rf.field("position", 0)[soil]
        H = x0[:, 1].max() + 0.5 * rf.dx
        f = rf.frame(rf.n_frames - 1)
        x = f["position"][soil]
        sv = f["effective_stress"][soil][:, 1, 1]
        depth = H - x0[:, 1]
        unit = (1 - N0) * (RHO_S - RHO_W * sat) * G  # gamma_sat - gamma_w saturated, gamma_d dry
        deep = depth > 0.1
        ratio = sv[deep] / (unit * depth[deep])
        settle = (x0[:, 1] - x[:, 1]).max() / H
        p_water = f["pressure"][rf.kind == WATER] if sat else None
        y_water = f["position"][rf.kind == WATER][:, 1] if sat else None
    return settle, ratio, p_water, y_water, H


def test_dry_column_at_rest(run_cli, tmp_path):
    """configs/soil_column.yaml, variant dry, 0.1 s. Measured: settlement 3.8e-7 of H, sigma'_v / (1 - n)
    rho_s g z = 1.000003 on average, 0.9995-1.0015 over the particles. Bounds: settlement 2e-6 of H, the
    mean ratio 0.1 %, any particle 0.5 % (the acceptance numbers are 0.5 % of H and 5 %)."""
    out = tmp_path / "dry.h5"
    r = run_cli("--config", "configs/soil_column.yaml", "--variant", "dry", "--set", "end_time=0.1", "--out", out,
                "--no-progress")
    assert r.returncode == 0, r.stderr
    settle, ratio, *_ = _column(out)
    assert settle < 2e-6, settle
    assert abs(ratio.mean() - 1) < 1e-3 and np.abs(ratio - 1).max() < 5e-3, (ratio.mean(), ratio.min(), ratio.max())


@pytest.mark.long
@pytest.mark.parametrize("k, pore_water, dx", [
    pytest.param(1e-3, "full_volume", 0.01, marks=pytest.mark.xdist_group("soil_column"), id="1e-3"),
    pytest.param(1e-5, "full_volume", 0.01, id="1e-5"),
    pytest.param(1e-3, "pore_volume", 0.01, id="1e-3-pore_volume"),
    pytest.param(1e-3, "pore_volume", 0.02, id="1e-3-pore_volume-dx0.02")])
def test_saturated_column_at_rest(run_cli, tmp_path, k, pore_water, dx, request):
    """configs/soil_column.yaml (saturated), 0.2 s: the soil must stay at rest with sigma'_v = (gamma_sat -
    gamma_w) z: the pore-pressure force -grad p / rho_s and the drag must not push or float it. Measured
    (the defaults with soil: c0 418 m/s, eq 36 at the flow's 24 m/s, density diffusion 0.1 in the gradient
    form) at k = 1e-3 m/s: settlement 0.001 % of H, mean ratio 1.002 (range 0.997-1.012), water floor
    pressure +0.01 %; at k = 1e-5 m/s (drag coefficient g / k ~ 1e6 1/s, stiff beside the EOS's step: the
    implicit drag must hold it) settlement 0.0003 %, ratio 1.000 (0.997-1.003), floor +1.3 % (with eq 36
    at c0 and no diffusion: 1.004 (0.995-1.018), +0.6 % and 1.004 (1.000-1.013)). With `wcsph.soil.pore_water:
    pore_volume` (each water particle in the soil n_i rho dx^2 heavy, at the pore velocity; docs/biot.md,
    "Pore water at its own volume"; K_f = 40 n M, c0 265 m/s, the pore water's step c0 / sqrt(n); the soil's
    pore-pressure force the share (1 - n_i) of the water's own pressure force) at k = 1e-3: settlement
    0.0008 %, ratio 1.0006 (0.996-1.005), floor +0.02 % (with the soil's own gradient of the Shepard pore
    pressure, as full_volume: 0.0013 %, 1.002 (0.997-1.012), +0.04 %); at dx 0.02 (k = 1e-3, 5 x 15
    soil particles) 0.013 %, 1.005 (0.936-1.064), +0.31 % (remeasured 2026-11-29: the same to the digits
    given, the settlement 1.2e-5 / 3.2e-6 / 7.9e-6 / 1.3e-4 of H in the order above). Bounds: settlement 3e-4
    of H, the mean ratio 1 %, any particle 8 %, the water 2.5 %, 1.3-2.3 times the largest measured (the
    acceptance numbers are 0.5 % of H and 5 %); the largest pore pressure the guard saw, below.
    pore_volume runs at two spacings (the shipped 0.01 and 0.02); full_volume at 0.01 only, its
    water-table column (test_column_with_a_water_table_at_rest) runs both."""
    if k == 1e-3 and pore_water == "full_volume":  # the config as shipped, shared with the two-stage column
        out, r = request.getfixturevalue("soil_column_run")
    else:
        out = tmp_path / "sat.h5"
        r = run_cli("--config", "configs/soil_column.yaml", "--set", f"wcsph.soil.permeability={k:g}",
                    "--set", f"wcsph.soil.pore_water={pore_water}", "--set", f"dx={dx}", "--out", out,
                    "--no-progress")
    assert r.returncode == 0, r.stderr
    settle, ratio, p, y, H = _column(out)
    assert settle < 3e-4, settle
    assert abs(ratio.mean() - 1) < 0.01 and np.abs(ratio - 1).max() < 0.08, (ratio.mean(), ratio.min(), ratio.max())
    bottom = y < y.min() + 0.5 * dx
    floor = np.mean(p[bottom] + RHO_W * G * y[bottom]) / (RHO_W * G * H) - 1
    assert abs(floor) < 0.025, floor
    # the largest pore pressure of a soil particle at any of the guard's checks (run attribute; what
    # guard.max_pore_pressure bounds, by default at 3 x g H_tank (rho_w + (1 - n) rho_s), 9x this): the
    # floor row's hydrostatic one. Measured 1.004 (k 1e-3) and 1.018 (k 1e-5) of rho_w g H, 0.980 with
    # pore_volume (the floor row's centre lies dx / 2 above the floor: 0.983; 1.008 with the soil's own
    # gradient); bound 2.5 %
    with RunFile(out) as rf:
        assert abs(rf.attrs["pore_pressure_max"] / (RHO_W * G * H) - 1) < 0.025, rf.attrs["pore_pressure_max"]
        vol = np.asarray(rf.diagnostics()["water_volume"], float)
    if pore_water == "pore_volume":
        # the water's own volume (m / rho): n of the column's 0.1 x 0.3 m; measured +1.14 / +2.17 % at dx
        # 0.01 / 0.02, the top row's n_i on the kernel's ramp (0.4 -> 1 over the surface), whose width is
        # the support: first order in dx. Bound 1.25 % per centimetre of dx
        assert abs(vol[0] / (N0 * 0.1 * 0.3) - 1) < 0.0125 * dx / 0.01, vol[0] / (N0 * 0.1 * 0.3)


def _water_table_column(path):
    """sigma'_v over its expected value, above the water table (deeper than 0.05 m) and below it; the
    largest settlement / H; the floor row's water pressure over rho_w g z_w. Expected (Terzaghi's effective
    stress, water at rest): gamma_d d above the table (d the depth), gamma_d d_w + gamma' (d - d_w) below,
    gamma_d = (1 - n) rho_s g, gamma' = (1 - n) (rho_s - rho_w) g, z_w the top of the water's rows."""
    with RunFile(path) as rf:
        dx, soil, water = rf.dx, rf.kind == SOIL, rf.kind == WATER
        f0, f = rf.frame(0), rf.frame(rf.n_frames - 1)
        x0, x = f0["position"][soil], f["position"][soil]
        zw = f0["position"][water][:, 1].max() + 0.5 * dx
        sv = f["effective_stress"][soil][:, 1, 1]
        pw, yw = f["pressure"][water], f["position"][water][:, 1]
    H = x0[:, 1].max() + 0.5 * dx
    d, dw = H - x0[:, 1], H - zw
    gd, gb = (1 - N0) * RHO_S * G, (1 - N0) * (RHO_S - RHO_W) * G
    ratio = sv / np.where(d < dw, gd * d, gd * dw + gb * (d - dw))
    bottom = yw < 0.5 * dx + 1e-3
    floor = float(np.mean(pw[bottom] + RHO_W * G * yw[bottom]) / (RHO_W * G * zw))
    return ratio[(d > 0.05) & (d < dw)], ratio[d > dw], (x0[:, 1] - x[:, 1]).max() / H, floor


@pytest.mark.long
@pytest.mark.parametrize("pore_water", ["full_volume", "pore_volume"])
def test_column_with_a_water_table_at_rest(run_cli, tmp_path, pore_water):
    """configs/soil_column.yaml with its water only to half the soil's height (0.15 m of 0.3 m): the soil
    above the table dry, below it saturated, 0.2 s. The pore-pressure force must give the buoyancy below the
    table and none above it, also in the rows where the table lies (a free surface of the pore water), so
    sigma'_v follows Terzaghi's effective stress with the dry unit weight above and the buoyant one below
    (`_water_table_column`). Measured, mean (extremes) of the ratio above / below the table:
    dx 0.01: full_volume 0.995 (0.990-1.002) / 1.003 (0.999-1.009), pore_volume 1.000 (0.995-1.004) /
    1.000 (0.996-1.006) (with the soil's own gradient of the Shepard pore pressure, before it took the
    water's own pressure sums: as full_volume);
    dx 0.02: full_volume 0.978 (0.962-1.004) / 0.991 (0.964-1.014), pore_volume 0.986 (0.953-1.030) /
    0.987 (0.947-1.024). Settlement at most 0.005 % of H; floor water pressure 1.000 (dx 0.01) and
    0.977-0.981 (dx 0.02) of rho_w g z_w. Bounds: means within 1 % at dx 0.01 and 2.5 % at dx 0.02, any
    particle within 1.5 % and 6 %, the measured largest rounded up; settlement 0.5 % of H (the acceptance
    number); floor pressure 1 % and 2.5 %."""
    for dx, b_mean, b_any, b_floor in ((0.01, 0.01, 0.015, 0.01), (0.02, 0.025, 0.06, 0.025)):
        out = tmp_path / f"wt_{dx}.h5"
        r = run_cli("--config", "configs/soil_column.yaml", "--set", f"dx={dx}", "--set",
                    f"wcsph.soil.pore_water={pore_water}", "--set", "water=[{min: [0.0, 0.0], max: [0.1, 0.15]}]",
                    "--out", out, "--no-progress")
        assert r.returncode == 0, r.stderr
        above, below, settle, floor = _water_table_column(out)
        for ratio in (above, below):
            assert abs(ratio.mean() - 1) < b_mean and np.abs(ratio - 1).max() < b_any, (dx, ratio.mean(),
                                                                                      ratio.min(), ratio.max())
        assert settle < 0.005, (dx, settle)
        assert abs(floor - 1) < b_floor, (dx, floor)


def _deposit(path):
    """Final deposit of the collapse: slope of the free surface (deg, line fitted where the surface is
    between 20 % and 80 % of the deposit height) and run-out beyond the column's face a = 0.1 m, taken
    where 98 % of the soil lies behind (the outermost grains thin to a single layer that lengthens as dx
    shrinks)."""
    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        dx = rf.dx
        f = rf.frame(rf.n_frames - 1)
        x = f["position"][soil]
        speed = np.linalg.norm(f["velocity"][soil], axis=1)
    edges = np.arange(0.0, x[:, 0].max() + dx, dx)
    col = np.digitize(x[:, 0], edges)
    top = np.array([x[col == k, 1].max() + 0.5 * dx if (col == k).any() else 0.0 for k in range(1, len(edges))])
    xc = edges[:-1] + 0.5 * dx
    height = top.max()
    sel = (top > 0.2 * height) & (top < 0.8 * height)
    slope = np.degrees(np.arctan(-np.polyfit(xc[sel], top[sel], 1)[0]))
    runout = np.percentile(x[:, 0], 98) - 0.1
    return slope, runout, np.median(speed)


@ti.kernel
def _plane_strain_compression(sig0: ti.types.ndarray(), rate: float, dt: float, steps: int, sin_phi: float,
                              c_cos: float, t_cut: float, kf: float, dim: ti.template(), out: ti.types.ndarray()):
    """A soil element under isochoric plane-strain compression along y (v_y = -rate y, v_x = rate x,
    v_z = 0), E = 1 MPa constant, nu 0.3: `steps` explicit steps of soil.stress_update from sig0."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        sig = ti.Matrix.zero(float, dim, dim)
        for a in ti.static(range(dim)):
            sig[a, a] = sig0[a]
        L = ti.Matrix.zero(float, dim, dim)
        L[0, 0] = rate
        L[1, 1] = -rate
        for _k in range(steps):
            sig, _g, _e = soil.stress_update(sig, L, dt, 1.0e6, 1.0e5, 0.0, 1.0e3, 0.3, kf, sin_phi, c_cos, t_cut,
                                             dim)
        for a in ti.static(range(dim)):
            for b in ti.static(range(dim)):
                out[a, b] = sig[a, b]


@pytest.mark.parametrize("dim, keys, phi, coh", [
    (2, {"friction_angle": 30.0}, 30.0, 0.0),
    (2, {"tan_phi": 0.5}, 30.0, 0.0),                      # the seed's form: sin(phi) = tan_phi
    (2, {"friction_angle": 40.0, "cohesion": 2000.0}, 40.0, 2000.0),
    (3, {"friction_angle": 35.0, "cohesion": 1000.0}, 35.0, 1000.0),
])
def test_yield_is_mohr_coulomb_in_plane_strain(ti_cpu, dim, keys, phi, coh):
    """Plane-strain compression of one element to failure, from the config keys to the stress: the
    principal stresses at failure must obey Mohr-Coulomb, sigma_1 = N sigma_3 + 2 c sqrt(N) with
    N = tan^2(45 deg + phi / 2) (3.00 at 30 deg, 4.60 at 40 deg; Rankine's passive coefficient). In 3D the
    start is anisotropic out of plane (sigma_zz 1.3 p0): the Drucker-Prager cone matches Mohr-Coulomb in
    plane strain once plastic flow has taken s_zz to zero (docs/biot.md), here after a plastic strain of
    ~1. Measured: |sigma_1 / (N sigma_3 + 2 c sqrt(N)) - 1| below 1e-14 in 2D and 3D (in 3D s_zz decays
    geometrically with the plastic strain and has vanished; sigma_zz = 11.0 kPa, the mean); bound 1e-6
    (rounding of 10^4 steps, and a residue of s_zz that a shorter run would leave)."""
    cfg = load_config(data={"mode": "wcsph_biot", "dim": dim, "dx": 0.01, "end_time": 0.1,
                            "tank": {"size": [0.1] * dim}, "soil_blocks": [{"min": [0.0] * dim, "max": [0.05] * dim}],
                            "wcsph": {"soil": keys}})
    sp = cfg.wcsph.soil
    assert sp.friction_angle_deg() == pytest.approx(phi, abs=1e-12)
    sin_phi, c_cos = soil.yield_constants(sp.friction_angle_deg(), sp.cohesion)
    p0 = 1.0e4
    sig0 = np.full(dim, p0)
    if dim == 3:
        sig0[2] = 1.3 * p0
    out = np.zeros((dim, dim))
    _plane_strain_compression(sig0, 1.0, 1.0e-4, 10000, sin_phi, c_cos, 1.0e9, soil.bulk_modulus_factor(dim, 0.3),
                              dim, out)
    s1, s3 = out[1, 1], out[0, 0]  # compression along y: y major, x minor
    n_phi = math.tan(math.radians(45.0 + phi / 2.0)) ** 2
    assert abs(out[0, 1]) < 1e-9 * p0
    assert s1 / (n_phi * s3 + 2.0 * coh * math.sqrt(n_phi)) == pytest.approx(1.0, abs=1e-6), (s1, s3, out)


@ti.kernel
def _simple_shear(sig0: ti.types.ndarray(), rate: float, dt: float, steps: int, sin_phi: float, kf: float,
                  out: ti.types.ndarray()):
    """A 2D soil element in simple shear (v_x = rate y: the sliding mode of an infinite slope or a shear
    band), E = 1 MPa constant, nu 0.3, no cohesion: `steps` explicit steps of soil.stress_update from sig0."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        sig = ti.Matrix.zero(float, 2, 2)
        sig[0, 0] = sig0[0]
        sig[1, 1] = sig0[1]
        L = ti.Matrix.zero(float, 2, 2)
        L[0, 1] = rate
        for _k in range(steps):
            sig, _g, _e = soil.stress_update(sig, L, dt, 1.0e6, 1.0e5, 0.0, 1.0e3, 0.3, kf, sin_phi, 0.0, 1.0e9, 2)
        for a in ti.static(range(2)):
            for b in ti.static(range(2)):
                out[a, b] = sig[a, b]


@pytest.mark.parametrize("phi", [19.8, 30.0, 40.0])
def test_simple_shear_slides_at_the_non_dilatant_angle(ti_cpu, phi):
    """Why a slope of this material slides below its Mohr-Coulomb angle. One element from the K0 state
    (sigma_xx = K0 sigma_yy, 1 kPa) sheared to a strain of 2 in simple shear. Reference (Davis 1968; Mohr's
    circle): at failure the in-plane Mohr circle touches the Mohr-Coulomb line, so the largest stress
    obliquity over all planes is phi; with no plastic volume change (the radial return, dilatancy psi = 0)
    steady simple shear needs the stress coaxial with the shear, s_xx = s_yy, and the plane that slides
    (the horizontal one) then carries tau / sigma_n = sin(phi) = tan(phi*), phi* = atan(sin phi) = 18.7 /
    26.6 / 32.7 deg at phi = 19.8 / 30 / 40 deg, not phi. Measured: mobilised angle asin(R / p) = phi to
    1e-14; tau / sigma_n on the horizontal plane 0.02 / 0.05 / 0.08 % below sin(phi) (the Jaumann rate
    leaves s_xx - s_yy of order tau^2 / G: 0.8 % at 10 kPa), its angle within 0.02 deg of phi*. Bounds
    1e-9 and 0.05 deg; and the sliding plane's angle at least 1 deg below phi (the gap that
    test_infinite_slope_slides_above_the_non_dilatant_angle measures on a layer)."""
    sin_phi = math.sin(math.radians(phi))
    out = np.zeros((2, 2))
    p0 = 1.0e3
    _simple_shear(np.array([0.3 / 0.7 * p0, p0]), 1.0, 1.0e-4, 20000, sin_phi, soil.bulk_modulus_factor(2, 0.3), out)
    p = 0.5 * (out[0, 0] + out[1, 1])
    radius = math.hypot(0.5 * (out[0, 0] - out[1, 1]), out[0, 1])
    assert math.degrees(math.asin(radius / p)) == pytest.approx(phi, abs=1e-9)
    sliding = math.degrees(math.atan(abs(out[0, 1]) / out[1, 1]))
    phi_star = math.degrees(math.atan(sin_phi))
    assert sliding == pytest.approx(phi_star, abs=0.05), (sliding, phi_star)
    assert sliding < phi - 1.0


@pytest.mark.parametrize("soil_keys, key, words", [
    ({"friction_angle": 30.0, "tan_phi": 0.5}, "wcsph.soil.tan_phi", "not both"),
    ({"tan_phi": 1.2}, "wcsph.soil.tan_phi", "exceeds 1"),
    ({"friction_angle": 90.0}, "wcsph.soil.friction_angle", ""),
    ({"friction_angle": 30.0, "cohesion": 100.0, "tension_cutoff": 200.0}, "wcsph.soil.tension_cutoff", "173.2"),
    ({"friction_angle": 30.0, "dilatancy_angle": 35.0}, "wcsph.soil.dilatancy_angle", "exceeds the friction angle"),
])
def test_friction_keys_rejected(soil_keys, key, words):
    """Bad friction input: one error naming the key (both forms at once, a tan_phi with no Mohr-Coulomb
    angle, an angle of 90 deg, a tension cut-off beyond c cot(phi) = 173.2 Pa at 30 deg, 100 Pa, a dilatancy
    angle above the friction angle)."""
    with pytest.raises(InputError) as exc:
        load_config(data={"mode": "wcsph_biot", "dim": 2, "dx": 0.01, "end_time": 0.1, "tank": {"size": [0.1, 0.1]},
                          "soil_blocks": [{"min": [0.0, 0.0], "max": [0.05, 0.05]}], "wcsph": {"soil": soil_keys}})
    assert f"'{key}'" in str(exc.value) and words in str(exc.value), str(exc.value)


def _check_slope(run_cli, tmp_path, beta, slides, *args):
    """configs/infinite_slope.yaml tilted to beta degrees (gravity rotated) with the extra CLI `args`: the
    layer's mean down-slope speed is above 1 cm/s if it `slides`, below 1 mm/s if it stands."""
    b = math.radians(beta)
    out = tmp_path / "slope.h5"
    r = run_cli("--config", "configs/infinite_slope.yaml", *args, "--set",
                f"gravity=[{G * math.sin(b):.8f}, {-G * math.cos(b):.8f}]", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    speed = _layer_speed(out)
    if slides:
        assert speed > 0.01, speed
    else:
        assert abs(speed) < 1e-3, speed


def _layer_speed(path):
    """Mean down-slope speed of the soil layer at the last frame (m/s)."""
    with RunFile(path) as rf:
        f = rf.frame(rf.n_frames - 1)
        return float(f["velocity"][rf.kind == SOIL][:, 0].mean())


@pytest.mark.parametrize("phi_keys, beta, slides", [
    ("wcsph.soil.friction_angle=30", 25.5, False),
    ("wcsph.soil.friction_angle=30", 27.5, True),
    ("wcsph.soil.friction_angle=40", 31.7, False),
    ("wcsph.soil.friction_angle=40", 33.7, True),
])
def test_infinite_slope_slides_above_the_non_dilatant_angle(run_cli, tmp_path, phi_keys, beta, slides):
    """configs/infinite_slope.yaml: a dry cohesionless layer 0.1 m deep, periodic along the slope, gravity
    tilted by beta, 0.6 s. Reference: the sliding mode of an infinite slope is simple shear parallel to
    it, and with this flow rule (deviatoric radial return: no plastic volume change, dilatancy psi = 0)
    steady simple shear needs the stress to be coaxial with it, s_xx = s_yy, so that tau / sigma_n on the
    slope plane is the Mohr circle's radius over its centre: the layer slides where tan(beta) > sin(phi),
    Davis's (1968) friction angle of a non-associated material, tan(phi*) = sin(phi) cos(psi) / (1 -
    sin(phi) sin(psi)) = sin(phi) at psi = 0: phi* = 26.57 deg at phi = 30 deg, 32.74 deg at 40 deg (an
    associated material, psi = phi, would stand up to beta = phi). Runs 1 deg either side. Measured mean
    down-slope speed at 0.6 s: 2e-5 / 0.056 m/s (phi 30: 25.5 / 27.5 deg), 4e-5 / 0.17 m/s (phi 40: 31.7 /
    33.7 deg); a standing layer comes to rest under the damping, a sliding one runs at ~(g sin(beta) -
    tau_f / (rho H)) / damping. Bounds: standing below 1 mm/s, sliding above 1 cm/s. At 28 deg with phi
    30 (below phi, above phi*) the layer slides at 0.054 m/s."""
    _check_slope(run_cli, tmp_path, beta, slides, "--set", phi_keys)


@pytest.mark.parametrize("beta, slides", [(29.0, False), (31.0, True)])
def test_infinite_slope_with_associated_flow_slides_at_phi(run_cli, tmp_path, beta, slides):
    """configs/infinite_slope.yaml, variant associated: phi = 30 deg with the dilatancy angle psi = phi, 0.9 s.
    Reference: Davis (1968), tan(phi*) = sin(phi) cos(psi) / (1 - sin(phi) sin(psi)) = tan(phi) at psi = phi:
    an associated Mohr-Coulomb layer stands up to beta = phi and slides beyond (limit analysis of the
    infinite slope, Taylor 1948), 1 deg either side. Measured mean down-slope speed: 29 deg: creeps at 3-8
    mm/s for ~0.6 s while it dilates (top +3 mm), then 5e-5 m/s at 0.9 s; 31 deg: 0.062 m/s at 0.9 s,
    dilating throughout (top +2.3 cm). With phi = 40 and psi = 40: 1e-5 m/s at 39 deg, 0.048 m/s at 41 deg
    (docs/biot.md). Bounds: standing below 1 mm/s, sliding above 1 cm/s, as the non-dilatant test."""
    _check_slope(run_cli, tmp_path, beta, slides, "--variant", "associated")


@pytest.mark.long
@pytest.mark.parametrize("pore_water, dx", [("full_volume", 0.01), ("pore_volume", 0.01),
                                             pytest.param("pore_volume", 0.005, id="pore_volume-dx0.005")])
@pytest.mark.parametrize("beta, slides", [(13.0, False), (15.0, True)])
def test_saturated_infinite_slope_slides_at_the_seepage_angle(run_cli, tmp_path, beta, slides, pore_water, dx):
    """configs/infinite_slope.yaml with its pores full of water up to the surface (density by continuity,
    k = 1 mm/s), 0.4 s: along the periodic slope gravity drives the water through the layer, seepage
    parallel to the slope with the water table at the surface. Reference: the infinite slope with
    parallel seepage (Taylor 1948) carries tau = gamma_sat H sin(beta) cos(beta) on sigma'_n = gamma' H
    cos^2(beta), so with the flow rule's sin(phi) in place of tan(phi) (the dry test above) it slides where
    tan(beta) > (gamma' / gamma_sat) sin(phi): gamma' / gamma_sat = 990 / 1990, beta* = 13.97 deg at phi
    = 30 deg (26.57 dry). The pore-pressure force and the drag must bring that half of the friction: runs
    1 deg either side, standing below 1 mm/s, sliding above 1 cm/s, as the dry test. Measured mean
    down-slope speed of the soil at 0.4 s: 13 deg 2e-5 / -5e-7 m/s, 15 deg 0.035 / 0.030 m/s (pore_volume /
    full_volume); 13.5 deg stands (1e-6 / 1e-5 m/s) and 14.5 deg slides (0.032 / 0.008 m/s, the second
    under the bound's 1 cm/s at this time). Where it stands the water runs through it at Darcy's q = k
    sin(beta): the water's mean velocity less the soil's is q / n with pore_volume (its particles carry the
    pore velocity) and q with full_volume (the mixture's): measured -2.4 / +1.9 % of that at 13 deg; bound
    3 %. At dx 0.005 (20 rows; the period along the slope halved to 0.05 m, which changes the speeds below
    by under 0.3 % and halves the run) the same bracket: 13 deg -4e-5 / -8e-5 m/s, 15 deg 0.034 / 0.022
    m/s, the seepage -0.5 / +1.2 % of Darcy's (pore_volume / full_volume; the test runs pore_volume there,
    about 40 s a case: full_volume's pair is measured, not run on every change; dx 0.02 would leave the periodic
    slope fewer than three neighbour-search cells). Run to 0.6 s, as before 2026-11-29 (the numbers of
    docs/biot.md): 13 deg 3e-6 / 6e-7 m/s, 15 deg 0.037 / 0.017 m/s, the seepage -2.1 / +2.0 %, and at dx
    0.005 9e-6 / -9e-6 m/s, 0.035 / 0.022 m/s, -1.1 / +0.8 %: the shorter run is the same bracket."""
    b = math.radians(beta)
    out = tmp_path / "wet_slope.h5"
    period = 0.1 if dx >= 0.01 else 0.05
    r = run_cli("--config", "configs/infinite_slope.yaml", "--set", f"tank.size=[{period}, 0.12]",
                "--set", f"soil_blocks=[{{min: [0.0, 0.0], max: [{period}, 0.1]}}]",
                "--set", f"water=[{{min: [0.0, 0.0], max: [{period}, 0.1]}}]",
                "--set", f"dx={dx}", "--set", "wcsph.density=continuity", "--set", f"wcsph.soil.pore_water={pore_water}", "--set",
                f"gravity=[{G * math.sin(b):.8f}, {-G * math.cos(b):.8f}]", "--set", "end_time=0.4", "--out", out,
                "--no-progress")
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        f = rf.frame(rf.n_frames - 1)
        soil_v = float(f["velocity"][rf.kind == SOIL][:, 0].mean())
        water_v = float(f["velocity"][rf.kind == WATER][:, 0].mean())
    if slides:
        assert soil_v > 0.01, soil_v
    else:
        assert abs(soil_v) < 1e-3, soil_v
        q = 1.0e-3 * math.sin(b) / (N0 if pore_water == "pore_volume" else 1.0)
        assert abs((water_v - soil_v) / q - 1) < 0.03, (water_v - soil_v, q)


def test_dry_column_collapse(run_cli, tmp_path):
    """configs/column_collapse.yaml at dx = a/10 and a/20 (0.6 s): the seed's tan(phi) = 0.5, Mohr-Coulomb
    phi = 30 deg, non-dilatant sliding angle phi* = atan(sin phi) = 26.6 deg (docs/biot.md), the bound's phi.
    Measured: slopes 13.6 / 17.4 deg, run-outs 0.166 / 0.156 m (6 % apart), the deposit at rest (median
    speed < 1 mm/s). Bounds: slope <= phi + 5 deg, run-out > 0, the two within 15 % (acceptance numbers),
    median speed < 1 cm/s (still flowing would be > 0.1 m/s)."""
    phi = np.degrees(np.arctan(math.sin(math.radians(30.0))))  # phi*, Davis's angle at psi = 0
    results = []
    for variant in ([], ["--variant", "fine"]):
        out = tmp_path / f"c{len(variant)}.h5"
        r = run_cli("--config", "configs/column_collapse.yaml", *variant, "--out", out, "--no-progress")
        assert r.returncode == 0, r.stderr
        results.append(_deposit(out))
    for slope, runout, speed in results:
        assert 0.0 < slope <= phi + 5.0, results
        assert runout > 0.0, results
        assert speed < 0.01, results
    (_, r1, _), (_, r2, _) = results
    assert abs(r1 - r2) / r2 < 0.15, results


@pytest.mark.long
@pytest.mark.parametrize("dx, pore_water", [(0.01, "full_volume"), (0.01, "pore_volume"),
                                            pytest.param(0.005, "pore_volume", id="dx0.005-pore_volume")])
def test_terzaghi_consolidation(run_cli, tmp_path, pore_water, dx):
    """configs/consolidation.yaml (seed 002 fig 10) at its dx = 0.01 m (5 particle columns, 20 rows of soil)
    and at 0.005 m (10 x 40):
    sine start u0 cos(pi y / H), H = 0.4 m (half layer on the floor), drained at the top. Exact: u_e / u0 =
    cos(pi y / H) exp(-pi^2 Tv), Tv = c_v t / H^2 with Terzaghi's c_v = k M / (rho_w g) (eq 55, M the
    constrained modulus; incompressible water). The water's sound speed is the default with soil, K_f =
    rho_w c0^2 = 40 M, so the model's own c_v, k / (rho_w g (1 / M + 1 / K_f)), is 0.976 of it. u_e is the
    water pressure minus that of the same run without the excess (the model's own hydrostatic state). Measured,
    largest |u_e / u0 - exact| over the soil at Tv 0.05 / 0.1 / 0.2 / 0.5: 0.012 / 0.009 / 0.002 / 0.001
    since the slip walls carry the soil's velocity along their faces with its gradient (docs/biot.md,
    Terzaghi consolidation; 0.033 / 0.034 / 0.019 / 0.003 before, when the 5-column layer settled 7.2 %
    more than M gives; at K_f = 20 M then: 0.027 / 0.028 / 0.031 / 0.003). Bound 0.025: half the
    acceptance value ("within 5 %" of u0), above the largest measured below (0.017).
    With the water's c0 = 20 m/s (K_f = 0.3 M) the layer consolidates at 0.23 of Terzaghi's c_v; with
    the soil started at rest instead of at its settlement rate an undrained wave of 0.2-0.4 u0 rings through
    the first isochrones (0.14 at Tv 0.05).
    With `wcsph.soil.pore_water: pore_volume` (storage n / K_f, the default K_f = 40 n M: c_v again 0.976 of
    Terzaghi's; the water starts at the pore velocity -(1 - n) / n v_s): 0.017 / 0.004 / 0.004 / 0.003
    (before the walls' change 0.034 / 0.031 / 0.020 / 0.005; 0.033 / 0.034 / 0.021 / 0.006 with the soil's
    own gradient of the Shepard pore pressure, as full_volume;
    with the soil's velocity in the pore water's continuity lagged by a step, as first built, the column
    went unstable at 0.07 s).
    At dx 0.005: 0.010 / 0.006 / 0.002 / 0.001 (full_volume) and 0.016 / 0.007 / 0.003 / 0.004
    (pore_volume); the layer settles 0.0468-0.0470 mm by Tv 0.5 at both spacings and in tanks 5, 10 or 20
    columns wide, against 0.0470 mm from M. The test runs pore_volume at both spacings and full_volume at
    0.01 only (its dx 0.005 pair, 50 s, is measured, not run on every change, as the saturated slope's
    above). Before the walls' change the error followed the tank's width
    more than the spacing (0.021 / 0.019 / 0.009 / 0.001 and 0.026 / 0.020 / 0.012 / 0.005 at dx 0.005 in
    10 columns, 0.036 / 0.034 / 0.018 / 0.003 and 0.046 / 0.036 / 0.024 / 0.011 in 5)."""
    out, base = tmp_path / "c.h5", tmp_path / "c0.h5"
    pw = ("--set", f"wcsph.soil.pore_water={pore_water}", "--set", f"dx={dx}")
    r = run_cli("--config", "configs/consolidation.yaml", *pw, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    r = run_cli("--config", "configs/consolidation.yaml", "--set", "wcsph.soil.initial_excess_pressure.amplitude=0",
                *pw, "--out", base, "--no-progress")
    assert r.returncode == 0, r.stderr
    cv = consolidation_coefficient(5e-3, 1.0e6, 0.3)
    for tv, (err, ue, exact) in isochrone_errors(out, base, 500.0, 0.4, 0.2, cv).items():
        assert err < 0.025, (tv, np.round(ue, 3), np.round(exact, 3))
    # the settlement the excess leaves: the top row's, less its twin's, at the frame nearest Tv 0.5, against
    # (u0 / M) int_0^0.2 cos(pi y / 0.4) dy (1 - exp(-pi^2 Tv)) = 0.0470 mm (the constrained modulus: the
    # layer is confined by the slip walls). Measured -0.4..+0.1 % at both spacings and in tanks 5-20
    # columns wide; +7.3 % (5 columns) before the slip walls carried the soil's velocity along their faces
    # with its gradient (docs/biot.md). Bound 1 %.
    with RunFile(out) as rf, RunFile(base) as rb:
        soil_ = rf.kind == SOIL
        y0 = rf.field("position", 0)[soil_][:, 1]
        top = y0 > y0.max() - 1e-9
        k = int(np.argmin(np.abs(rf.times - 0.5 * 0.4**2 / cv)))
        tv = cv * rf.times[k] / 0.4**2
        settle = float(np.mean(rb.frame(k)["position"][soil_][top, 1] - rf.frame(k)["position"][soil_][top, 1]))
    expected = 500.0 / constrained_modulus(1.0e6, 0.3) * 0.4 / math.pi * (1.0 - math.exp(-math.pi**2 * tv))
    assert abs(settle / expected - 1) < 0.01, (settle, expected)


@pytest.mark.long
def test_soft_pore_water_warns_and_is_recorded(run_cli, tmp_path):
    """A config whose water is softer than 40 M (consolidation.yaml with the seed-like c0 = 20 m/s: K_f =
    0.4 MPa, M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) = 1.346 MPa) warns, naming the keys, and the run file
    records K_f / M = 0.297; c0 = 164 m/s (K_f = 20 M, the floor before, whose B = 0.952 left the undrained
    check short of 0.95) warns too; the default sound speed records 40 and does not warn."""
    import h5py

    soft, stiff = tmp_path / "soft.h5", tmp_path / "stiff.h5"
    r = run_cli("--config", "configs/consolidation.yaml", "--set", "end_time=0.002", "--set",
                "wcsph.water.sound_speed=20", "--out", soft, "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "wcsph.water.sound_speed" in r.stderr and "wcsph.soil.youngs_modulus" in r.stderr, r.stderr
    r2 = run_cli("--config", "configs/consolidation.yaml", "--set", "end_time=0.002", "--out", stiff, "--no-progress")
    assert r2.returncode == 0, r2.stderr
    assert "wcsph.water.sound_speed" not in r2.stderr, r2.stderr
    m = 1.0e6 * 0.7 / (1.3 * 0.4)
    with h5py.File(soft) as f:
        assert f.attrs["pore_water_modulus_ratio"] == pytest.approx(1000.0 * 20.0**2 / m, rel=1e-12)
    with h5py.File(stiff) as f:
        assert f.attrs["pore_water_modulus_ratio"] == pytest.approx(40.0, rel=1e-9)
    r3 = run_cli("--config", "configs/consolidation.yaml", "--set", "end_time=0.0005", "--set",
                 f"wcsph.water.sound_speed={(20.0 * m / 1000.0) ** 0.5!r}", "--out", tmp_path / "k20.h5",
                 "--no-progress")
    assert r3.returncode == 0, r3.stderr
    assert "wcsph.water.sound_speed" in r3.stderr, r3.stderr


@pytest.mark.parametrize("pore_water", ["full_volume", "pore_volume"])
def test_dealt_moving_list_leaves_every_particle_as_it_was(ti_cpu, monkeypatch, pore_water):
    """A parallel scene with soil deals its list of moving particles to the threads in chunks
    (solver.DEAL_CHUNK, `_k_moving_list`), so that each thread's block of every loop samples the whole scene.
    The list must stay a permutation of the moving particles, and the particles' states must not depend on
    it: each particle's update reads only its neighbours, the loop order changes sums of diagnostics only.
    configs/consolidation.yaml (433 particles, soil + water) run 60 steps with its loops parallel, the list
    in cell order and dealt to 2 threads: positions, velocities and stresses equal bit for bit. With
    pore_volume too, whose soil gathers its pore-pressure force from the water's shares (no atomic sums)."""
    import taichi_sph.wcsph.solver as sv
    from taichi_sph.run import TimeStepper
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    cfg = load_config("configs/consolidation.yaml", ["precision=f64", f"wcsph.soil.pore_water={pore_water}"])
    monkeypatch.setattr(sv, "SERIAL_BELOW_SOIL", 0)
    out = {}
    for deal in (1, 2):
        monkeypatch.setattr(sv, "deal_threads", lambda has_soil, serial, d=deal: d)
        solver = make_solver(cfg, build_scene(cfg))
        assert not solver.serial and solver.deal == deal
        solver.initial_diagnostics()
        n = solver.n_moving[None]
        ids = solver.moving_ids.to_numpy()[:n]
        moving = np.nonzero(solver.fmask.to_numpy()[: solver.n] >= 1)[0]
        np.testing.assert_array_equal(np.sort(ids), moving)
        if deal == 2:  # dealt: not the cell order any more
            assert np.any(np.diff(ids) < 0)
        stepper = TimeStepper(cfg, solver.g_abs)
        for _ in range(60):
            solver.step(stepper.choose(0.0, solver.propose_dt())[0])
        f = solver.fields_by_id()
        out[deal] = (f, solver.soil.sig.to_numpy()[solver._id_order()])
    for key in ("position", "velocity"):
        np.testing.assert_array_equal(out[1][0][key], out[2][0][key])
    np.testing.assert_array_equal(out[1][1], out[2][1])
