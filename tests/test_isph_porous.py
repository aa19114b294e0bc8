"""Mode isph in porous ground: porosity from soil markers (eq 32), the eq 9 coefficients with the drag
implicit in the projection, and the reduction to free water at eps = 1."""

import numpy as np
import pytest

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.kinds import WALL, WATER

from .conftest import ROOT, cli

G = 9.81


def _markers_and_eps(ti_cpu, data, points):
    """eps and D50 at `points` from the markers of a config (in-process, shared CPU runtime)."""
    import taichi as ti

    from taichi_sph.config import load_config
    from taichi_sph.isph.porosity import MarkerSet
    from taichi_sph.scene import build_scene
    from taichi_sph.sph.kernels import SUPPORT_FACTOR

    cfg = load_config(data=data)
    scene = build_scene(cfg)
    ms = MarkerSet(scene.markers, cfg.dim, scene.lo, scene.hi, SUPPORT_FACTOR * cfg.dx)
    n = len(points)
    x = ti.Vector.field(cfg.dim, float, n)
    x.from_numpy(np.asarray(points, float))
    mask = ti.field(ti.i32, n)
    mask.fill(1)
    eps = ti.field(float, n)
    d50 = ti.field(float, n)
    reach = ti.field(ti.i32, n)
    ms.porosity(x, mask, n, eps, d50, reach)
    return eps.to_numpy(), d50.to_numpy()


def _soil_config(regions, dim=2):
    size = [0.3, 0.4] if dim == 2 else [0.2, 0.2, 0.4]
    return {"mode": "isph", "dim": dim, "dx": 0.01, "end_time": 0.1, "tank": {"size": size},
            "water": [{"min": [0.0] * dim, "max": size[:-1] + [0.05]}], "soil": {"regions": regions}}


@pytest.mark.parametrize("dim", [2, 3])
def test_porosity_across_a_flat_soil_surface(ti_cpu, dim):
    """eq 32 along a vertical line through a flat surface at z = 0.2: 1 above (S <= 1/2 there),
    eps0 deep inside, monotone in between, and the transition only on the soil side. Exact up to
    round-off except the plateau (the marker lattice's kernel sum is 1 within 0.1 %: 1e-3)."""
    eps0 = 0.3
    lo = [0.0] * (dim - 1) + [0.0]
    hi = ([0.3] if dim == 2 else [0.2, 0.2]) + [0.2]
    cfg = _soil_config([{"min": lo, "max": hi, "eps0": eps0, "d50": 0.002}], dim)
    z = np.linspace(0.05, 0.35, 121)
    mid = [0.15] if dim == 2 else [0.1, 0.1]
    pts = np.array([mid + [zz] for zz in z])
    eps, d50 = _markers_and_eps(ti_cpu, cfg, pts)
    re = 0.024
    # strictly above the face; on the face itself the discrete marker sum exceeds 1/2 slightly
    # (eps = 0.994 - 0.996 there)
    assert np.all(eps[z > 0.2] == 1.0)
    assert np.all(eps[np.isclose(z, 0.2)] > 0.99)
    assert np.all(np.abs(eps[z < 0.2 - re] - eps0) < 1e-3)
    assert np.all(np.diff(eps) >= -1e-12)  # rises monotonically towards the surface
    assert np.all(eps[(z < 0.2) & (z > 0.2 - 0.5 * re)] < 1.0)  # the transition lies inside the soil
    assert np.allclose(d50[z < 0.2], 0.002)


def test_porosity_near_a_wall_keeps_the_ground_value(ti_cpu):
    """Ground that meets a wall runs on into it: next to the wall eps stays eps0 (markers stopping at
    the wall face would give eps -> 1 there, a free channel along every wall)."""
    cfg = _soil_config([{"min": [0.0, 0.0], "max": [0.3, 0.2], "eps0": 0.4, "d50": 0.002}])
    pts = np.array([[x, 0.1] for x in (0.005, 0.01, 0.295)] + [[0.15, 0.005]])
    eps, _ = _markers_and_eps(ti_cpu, cfg, pts)
    assert np.all(np.abs(eps - 0.4) < 1e-3), eps


def test_layered_ground_gives_two_plateaus(ti_cpu):
    """Coarse armour (eps0 0.45, D50 2 cm) over a fine core (eps0 0.3, D50 2 mm): deeper than one
    support radius from the layer interface each layer's own eps0 and D50 (1e-3, as above)."""
    cfg = _soil_config([
        {"min": [0.0, 0.0], "max": [0.3, 0.2], "eps0": 0.45, "d50": 0.02},
        {"min": [0.0, 0.0], "max": [0.3, 0.1], "eps0": 0.3, "d50": 0.002},
    ])
    z = np.linspace(0.01, 0.19, 91)
    eps, d50 = _markers_and_eps(ti_cpu, cfg, np.array([[0.15, zz] for zz in z]))
    re = 0.024
    core = z < 0.1 - re
    armour = (z > 0.1 + re) & (z < 0.2 - re)
    assert np.all(np.abs(eps[core] - 0.3) < 1e-3)
    assert np.all(np.abs(eps[armour] - 0.45) < 1e-3)
    assert np.all(np.abs(d50[core] - 0.002) < 1e-6) and np.all(np.abs(d50[armour] - 0.02) < 1e-6)
    # between the plateaus eps changes monotonically
    band = (z > 0.1 - re) & (z < 0.1 + re)
    assert np.all(np.diff(eps[band]) >= -1e-12)


FREEFALL_COARSE_END = 3.5  # s: the settled pool's volume is measured over its last 0.5 s


@pytest.fixture(scope="module")
def freefall_coarse(tmp_path_factory):
    """configs/freefall.yaml, variant coarse, run once to FREEFALL_COARSE_END (past the shipped 2.5 s: the
    pool meets the layer at 2.3-2.6 s, see test_freefall_coarse_volume_and_fraction_in_layer): its run
    file and the CLI's CompletedProcess. The tests that read it are marked xdist_group("freefall_coarse")."""
    out = tmp_path_factory.mktemp("ff") / "ff.h5"
    return out, cli("--config", "configs/freefall.yaml", "--variant", "coarse", "--set",
                    f"end_time={FREEFALL_COARSE_END}", "--out", out, "--no-progress")


@pytest.mark.long  # its group computes the fixture
@pytest.mark.xdist_group("freefall_coarse")  # reads the free fall's run (fixture freefall_coarse)
def test_markers_stored_in_the_run_file(freefall_coarse):
    """/markers holds the SPEC 8 names; the seed's 21 x 21 x 21 markers lie inside the tank."""
    out, r = freefall_coarse
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        pos = rf.h5["markers/position"][...]
        assert rf.h5["markers/porosity"].shape == rf.h5["markers/d50"].shape == (len(pos),)
        inside = np.all((pos >= -1e-9) & (pos <= np.array([0.2, 0.2, 0.7]) + 1e-9), axis=1)
        assert inside.sum() == 11**3  # dx = 2 cm in this variant: 0.2 m / 2 cm + 1 nodes per axis
        assert "porosity" in rf.field_names


def test_eps_one_is_free_water(run_cli, tmp_path):
    """Ground with eps0 = 1 compiles and runs every porous term (markers, Cr, a, b, D, wall share) and
    must give the free-water result: same positions after a violent 0.1 s to round-off (1e-9 m)."""
    base = ["--config", "configs/dambreak.yaml", "--set", "dx=0.01", "--set", "end_time=0.1", "--set",
            "dt=0.002", "--set", "output.every=0.1", "--no-progress"]
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    r = run_cli(*base, "--out", a)
    assert r.returncode == 0, r.stderr
    r = run_cli(*base, "--set", "soil.regions=[{min: [0, 0], max: [0.6, 0.1], eps0: 1.0, d50: 0.001}]",
                "--out", b)
    assert r.returncode == 0, r.stderr
    with RunFile(a) as ra, RunFile(b) as rb:
        assert "porosity" in rb.field_names
        assert np.all(rb.frame(-1)["porosity"] == 1.0)
        assert np.max(np.abs(ra.frame(-1)["position"] - rb.frame(-1)["position"])) < 1e-9


@pytest.mark.parametrize("dt", [0.001, 0.0005])
def test_darcy_column_terminal_velocity(run_cli, tmp_path, dt):
    """A water slab in uniform ground (eps0 0.4, D50 2 mm), free surfaces above and below, falls at
    the terminal Darcy velocity: the root of a vD + b vD^2 = g / eps (16.4 mm/s), with its pressure at
    the surface value rho_w g dx / 2 = 49.05 Pa throughout (Darcy's law with no head: gravity alone
    drives the flow, so no pressure gradient may). Measured at dt 1 / 0.5 ms, 0.3 s: mean vD of the
    slab's core +0.03 / +0.01 %, its spread (standard deviation) 0.68 / 0.81 % of vD; the pressure after
    the first step -3.3..+9.9 / -8.8..+17.0 Pa from the surface value (the slab at rest would hold rho_w
    g H = 1324 Pa at its bottom). Before the shift's anti-pairing took a wall pair at the pore water's
    rest distance from the wall (docs/isph.md, "The shift's anti-pairing at walls in the ground"), it
    pushed the columns off the slip walls: +0.09 / -0.01 %, spread 1.35 / 1.75 %, pressure up to +28.7
    / +57.0 Pa. Bounds: the core's vD 0.1 %, three times the larger measured (the acceptance value is
    2 %; the implicit drag makes the steady state exact up to the SPH gradient of the uniform surface
    pressure), its spread 1 %, the pressure 20 Pa (1.5 % of rho_w g H; the measured 17 Pa grows as the
    step falls, through eq 31's alpha / dt^2)."""
    from taichi_sph.isph.porosity import terminal_darcy_velocity

    out = tmp_path / "dc.h5"
    r = run_cli("--config", "configs/darcy_column.yaml", "--set", f"dt={dt}", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    vt = terminal_darcy_velocity(0.4, 1.0e-6, 0.002)
    with RunFile(out) as rf:
        w = rf.kind == 0
        f = rf.frame(-1)
        z = f["position"][w][:, -1]
        core = (z > np.percentile(z, 20)) & (z < np.percentile(z, 80))
        vz = -f["velocity"][w][core, -1]
        assert abs(vz.mean() / vt - 1) < 0.001, vz.mean() / vt - 1
        assert vz.std() / vt < 0.01, vz.std() / vt
        assert np.all(np.abs(f["porosity"][w] - 0.4) < 1e-3)
        dp = np.array([rf.frame(i)["pressure"][w] - 0.5 * 1000.0 * 9.81 * rf.dx for i in range(1, rf.n_frames)])
    print(f"Darcy slab, dt {dt}: vD {vz.mean() / vt - 1:+.4%}, spread {vz.std() / vt:.3%}, "
          f"p - p_s {dp.min():+.2f}..{dp.max():+.2f} Pa")
    assert np.max(np.abs(dp)) < 20.0, (dp.min(), dp.max())


@pytest.mark.parametrize("dt", [0.001, 0.0005])
def test_still_water_over_fine_sand(run_cli, tmp_path, dt):
    """10 cm of saturated fine sand (D50 0.1 mm, eps0 0.3: D ~ 2000 at dt 1 ms) under 10 cm of free
    water stays at rest with hydrostatic pressure, at dt 1 and 0.5 ms (the drag number D = 1 + c (a + b
    |v|) follows the step). Measured (2D, dx 1 cm, 0.3 s) at dt 1 / 0.5 ms: pressure of the bottom row
    within 3.4e-6 / 1.4e-5 of rho g (H - z), max speed 4.3e-4 / 8.5e-4 sqrt(g H) (early, then falling; at
    dt 1 ms 6.5e-4 m/s at 15 ms, 1.1e-4 m/s at 0.3 s), water volume -0.024 / -0.026 %. Bounds: pressure
    5e-5 (the acceptance value is 2 %), max speed 2e-3 sqrt(g H) (the free-water hydrostatic bound is 1e-2;
    the start-up transient doubles as the step halves, eq 31's alpha / dt^2), volume 0.1 %. Before gravity
    entered the PPE through its potential, the water above the sand fell freely and the sand's pressure
    was 2.4 rho g H."""
    cfg = tmp_path / "sand.yaml"
    cfg.write_text(
        f"mode: isph\ndim: 2\ndx: 0.01\nend_time: 0.3\ndt: {dt}\n"
        "output: {path: sand.h5, every: 0.05}\ntank: {size: [0.2, 0.3]}\n"
        "water:\n  - {min: [0.0, 0.0], max: [0.2, 0.1], porosity: 0.3}\n  - {min: [0.0, 0.1], max: [0.2, 0.2]}\n"
        "soil:\n  regions:\n    - {min: [0.0, 0.0], max: [0.2, 0.1], eps0: 0.3, d50: 0.0001}\n")
    out = tmp_path / "sand.h5"
    r = run_cli("--config", cfg, "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        w = rf.kind == 0
        f = rf.frame(-1)
        pos, p = f["position"][w], f["pressure"][w]
        top = pos[:, 1].max() + 0.005  # the surface is half a spacing above the top row
        H = top
        bottom = pos[:, 1] < pos[:, 1].min() + 1e-6
        hydro = 1000.0 * G * (top - pos[bottom, 1])
        d = rf.diagnostics()
        dp = np.max(np.abs(p[bottom] / hydro - 1))
        speed = np.max(d["max_speed"]) / np.sqrt(G * H)
        dvol = d["water_volume"][-1] / d["water_volume"][0] - 1
    print(f"fine sand, dt {dt}: bottom pressure {dp:.2e}, max speed {speed:.2e} sqrt(gH), volume {dvol:+.4%}")
    assert dp < 5e-5, dp
    assert speed < 2e-3, speed
    assert abs(dvol) < 1e-3, dvol


@pytest.fixture(scope="module")
def permeameter_runs(tmp_path_factory):
    """configs/permeameter.yaml at dx 5 mm (20 spacings over the 10 cm plug) at dt 1 and 0.5 ms, to
    0.44 s, with the default surface test in the ground (the cone, isph.ground_surface_cone 60): the
    level above the plug (porosity.column_level) against the falling-head ODE with the inertia of the
    column and the plug, the plug core's share of Dirichlet rows, and its water per pore volume counted
    without a kernel: each particle a slab of the pore lattice's row spacing dx / eps0^(1/2)
    (porosity.slab_count; the core is 9.6 rows tall, and a count of centres moves by a row as rows cross
    its faces), times its bulk volume dx^2 / eps0, over the core's area."""
    from taichi_sph.isph.porosity import slab_count

    out = {}
    for dt in (0.001, 0.0005):
        path = tmp_path_factory.mktemp("pm") / "pm.h5"
        t, h, frames, w, dx = _permeameter_run(path, dt)
        core = [(w & f["active"] & (f["position"][:, 1] > 0.312) & (f["position"][:, 1] < 0.388)) for f in frames]
        flagged = np.mean([f["free_surface"][c].mean() for f, c in zip(frames, core)])
        rows = [f["position"][w & f["active"]][:, 1] for f in frames]
        fill = np.array([slab_count(z, 0.312, 0.388, dx / 0.4**0.5) * dx**2 / 0.4 / (0.10 * 0.076) for z in rows])
        dev, half, dev_q = _level_deviation(t, h)
        out[dt] = (t, dev, half, flagged, fill, dev_q)
    return out


def _permeameter_run(path, dt, *sets):
    """configs/permeameter.yaml at dx 5 mm and dt to 0.44 s (frames every 10 ms), with `--set` overrides
    `sets`: the frame times, the level above the plug (porosity.column_level), the frames, the water mask
    and dx."""
    from taichi_sph.isph.porosity import column_level

    extra = [a for s in sets for a in ("--set", s)]
    r = cli("--config", "configs/permeameter.yaml", "--set", "dx=0.005", "--set", f"dt={dt}", "--set", "end_time=0.44",
            "--set", "output.every=0.01", *extra, "--out", path, "--no-progress")
    assert r.returncode == 0, r.stderr
    with RunFile(path) as rf:
        w = rf.kind == 0
        frames = [rf.frame(i) for i in range(rf.n_frames)]
        h = np.array([column_level(f["position"][w & f["active"]][:, -1], 0.40, rf.dx) for f in frames])
        return rf.times, h, frames, w, rf.dx


def _level_deviation(t, h):
    """The permeameter's level h(t) against the falling-head ODE with inertia (h / ref - 1), the first half
    of the drainage (the quasi-steady ODE's h above h0 / 2), and against the quasi-steady ODE."""
    from taichi_sph.isph.porosity import falling_head_deviation

    fh = falling_head_deviation(t, h, 0.10, 0.4, 0.01)  # configs/permeameter.yaml: plug length, eps0, D50
    return fh.deviation, fh.first_half, fh.deviation_quasi


def test_air_entry_suction_keeps_the_permeameter_on_the_ode(tmp_path):
    """isph.air_entry_suction (off by default; configs/porous_dambreak.yaml sets it) clamps the pore
    water's pressure at minus the ground's air-entry suction. At 2 rho_w g H, H = 0.3 m the water's height
    (5886 Pa), the permeameter at dx 5 mm still follows the falling-head ODE with inertia over the first
    half at dt 1 and 0.5 ms, within the acceptance's 3 % and the time steps within 3 points of each
    other: the clamp acts on the draining ground's tension, not on the plug's Darcy flow. Measured (one
    run each, the suite's threads): largest deviation 0.77 / 2.18 % at dt 1 / 0.5 ms, the time steps
    within 1.4 points of each other (without the key, one thread: 0.77 / 2.18 %, 1.4 points; before the
    shift's anti-pairing took a wall pair at the pore water's rest distance from the wall, docs/isph.md,
    0.46 / 1.43 %, 1.2 points, and without the key 0.46 / 1.38 %, 1.1 points; before pore water in
    drained ground joined the tension rule 0.50 / 1.57 %, 1.1 points; before the corrector took each particle's own wall pressure
    0.27 / 0.89 %, 0.98 points). Bound 3 %, the acceptance value, as in the test without the key."""
    devs = {}
    for dt in (0.001, 0.0005):
        t, h, _, _, _ = _permeameter_run(tmp_path / f"pm_{dt}.h5", dt, "isph.air_entry_suction=5886")
        dev, half, _ = _level_deviation(t, h)
        assert half.sum() > 20
        devs[dt] = dev[half]
    n = min(len(d) for d in devs.values())
    spread = float(np.max(np.abs(devs[0.001][:n] - devs[0.0005][:n])))
    worst = {dt: float(np.max(np.abs(d))) for dt, d in devs.items()}
    print("air entry suction: largest deviation per dt", worst, "spread", spread)
    assert max(worst.values()) < 0.03 and spread < 0.03, (worst, spread)


@pytest.mark.xdist_group("permeameter_runs")  # one worker computes the shared runs once
def test_permeameter_follows_the_falling_head_ode_at_two_time_steps(permeameter_runs):
    """The water level above the plug follows the falling-head ODE over the first half of the drainage
    (h from 0.2 to 0.1 m) at dt 1 and 0.5 ms. The reference keeps the inertia of the column and the plug,
    (h + Cr L) dvD/dt = g (h + L) - eps L (a vD + b vD^2) from rest (porosity.falling_head_level; its
    steady state is SPEC 5's quasi-steady ODE, which the column, starting from rest, trails by 2.5 % of
    h after 50 ms and 3.3 % at 0.4 s for that reason alone). Measured (one thread): largest deviation
    -0.8 / -2.2 % at dt 1 / 0.5 ms, the time steps within 1.4 points of each other; from the quasi-steady
    ODE 0.0..+3.3 / +2.7 % (before the shift's anti-pairing took a wall pair at the pore water's rest
    distance from the wall, docs/isph.md: +0.5 / -1.4 % (-1.5 % at 0.25 ms), 1.1 points, and -1.8 / -1.3 %,
    0.5 points in a second one-thread run of the same code, the scatter of a 5 mm plug; before pore water
    in drained ground joined the tension rule: -0.5 / -1.0 %, 0.53 points; before the corrector took each particle's own wall pressure: -0.8 /
    -2.6 %, 1.8 points; before the cone test looked for air: -0.3 / -1.0 %, 1.2 points). Bound 3 %, the
    acceptance value, for both and for the spread. Before the cone test became the default (eq 34's count alone in the ground) the level read
    -15.5 / +2.0 / +16.8 % from the quasi-steady ODE at 1 / 0.5 / 0.25 ms; with the cone but the
    kernel-gradient correction inside the plug, the column bounced on the plug at 0.25 ms (docs/isph.md,
    "Surface test in the ground")."""
    devs = []
    for dt, (t, dev, half, _, _, dev_q) in permeameter_runs.items():
        assert half.sum() > 20
        assert np.max(np.abs(dev[half])) < 0.03, (dt, dev[half].min(), dev[half].max())
        # against the quasi-steady ODE, measured 0.0..+3.3 %: never ahead of it by more than 1 % (without
        # inertia it drains fastest), behind it by at most its lag behind the inertial ODE (3.3 % at 0.44 s)
        # and 1.2 points more
        assert np.all(dev_q[half] > -0.01) and np.all(dev_q[half] < 0.045), (dt, dev_q[half].min(), dev_q[half].max())
        devs.append(dev[half])
    n = min(len(d) for d in devs)
    assert np.max(np.abs(devs[0][:n] - devs[1][:n])) < 0.03


@pytest.mark.long
def test_fine_permeameter_level_does_not_follow_the_shift_number(tmp_path):
    """The permeameter at dx 2.5 mm at dt 1 and 0.5 ms (dt / dx 0.4 and 0.2 s/m): the particle shift is one
    explicit diffusion step with coefficient A h |u|, whose number A |u| dt / h reaches 0.33 in the plug at
    1 ms; taken in one piece it overshot there, the plug's pore water held 0.99 of its pores against 1.02,
    and the level ran 3.8 % slow, 3.6 points from 0.5 ms (docs/isph.md, "Shifting in substeps"). With the
    shift in substeps where that number passes 0.25: largest deviation from the ODE with inertia over the
    first half +0.85 / +0.37 % at 1 / 0.5 ms, 0.76 points apart (one thread; before the shift's anti-pairing
    took a wall pair at the pore water's rest distance from the wall, docs/isph.md, +0.51 / +0.40 %, 0.25
    points); the 1 ms run takes substeps (421 of its 440 steps), the 0.5 ms run none. Bounds: 3 % (the
    acceptance value) and 1 point for the spread (a quarter of the one-piece shift's 3.6 points)."""
    from taichi_sph.isph.porosity import column_level

    devs, subs = {}, {}
    for dt in (0.001, 0.0005):
        path = tmp_path / f"pm_{dt}.h5"
        r = cli("--config", "configs/permeameter.yaml", "--set", "dx=0.0025", "--set", f"dt={dt}", "--set",
                "end_time=0.44", "--set", "output.every=0.01", "--out", path, "--no-progress")
        assert r.returncode == 0, r.stderr
        with RunFile(path) as rf:
            w = rf.kind == 0
            h = np.array([column_level(rf.frame(i)["position"][w & rf.frame(i)["active"]][:, -1], 0.40, rf.dx)
                          for i in range(rf.n_frames)])
            t = rf.times
            subs[dt] = int(np.count_nonzero(np.asarray(rf.diagnostics()["shift_substeps"]) > 1))
        dev, half, _ = _level_deviation(t, h)
        assert half.sum() > 20
        devs[dt] = dev[half]
        assert np.max(np.abs(dev[half])) < 0.03, (dt, dev[half].min(), dev[half].max())
    assert subs[0.001] > 0 and subs[0.0005] == 0, subs
    n = min(len(d) for d in devs.values())
    assert np.max(np.abs(devs[0.001][:n] - devs[0.0005][:n])) < 0.01, (devs[0.001][:n], devs[0.0005][:n])


@pytest.mark.parametrize("option, spread_bound, level_bound", [
    ("isph.ground_density_support=pore", 0.03, 0.10),
    ("isph.ground_shifting=1.5", 0.025, 0.07)])
def test_coarse_permeameter_level_does_not_depend_on_the_time_step(tmp_path, option, spread_bound, level_bound):
    """The permeameter at dx 1 cm (the plug ten spacings long, six pore particles a row) with one of two
    options, at the validation grid's dt 0.25 / 0.5 / 1 ms: the level against the falling-head ODE with
    inertia over the first half, and the plug core's share of Dirichlet rows.

    With the shift's coefficient in the ground 1.5 instead of 2 (isph.ground_shifting; docs/isph.md, "A
    weaker shift for pore water"): measured (one thread) -5.9 / -5.2 / -4.2 %, 1.74 points apart, and
    -3.9..-5.9 % over 0.25-1.1 ms (2.1 points). Bounds: the spread 2.5 points, the level 7 %.

    With eq 31's stabilisation read over the pore lattice's support (isph.ground_density_support: pore).
    Measured (one thread): -8.4 / -8.2 / -5.7 %,
    at one time at most 2.83 points apart (before the shift's anti-pairing took a wall pair at the pore
    water's rest distance from the wall, docs/isph.md: -7.1 / -6.7 / -7.4 %, 0.68 points; with dx moved
    by 1e-5 of itself -7.1 / -6.7 / -6.8..-7.1 %;
    with the pore sum's cells taken in another order (round-off) the 1 ms run read -9.2 %, 2.6 points
    from the others. Over 0.25-1.1 ms the level still moves between -4.7 and -8.6 % (docs/isph.md, "The
    stabilisation over the pore lattice's support"): the grid's steps agree, not every step.

    The default support is not tested for this, because it does not hold it at 10 mm. Its plug has two
    branches over dt, about -4 % at 0.4-0.75 ms and -7 to -8.7 % at 0.25-0.3 and 0.9-1.1 ms (docs/isph.md,
    "The 10 mm plug's two branches"); the grid reads -7.7 / -5.9 / -4.4 % (3.38 points; before the
    anti-pairing change -6.7 / -4.0 / -8.7 %, 4.65 points). This test ran the default at 0.25 / 0.5 ms
    (one on each branch) against the same 3 points and read 2.85 points with one thread, 3.12 with the
    test suite's threads: the sum's order decided it.

    Bounds: the spread 3 points (the acceptance's; the worst measured 2.83), the level 10 % (the coarse
    plug's own error, -9.2 % at worst), the core 0.5 % (both options)."""
    devs = {}
    for dt in (0.00025, 0.0005, 0.001):
        t, h, frames, w, dx = _permeameter_run(tmp_path / f"pm_{dt}.h5", dt, "dx=0.01", option)
        assert dx == 0.01
        dev, half, _ = _level_deviation(t, h)
        assert half.sum() > 20
        devs[dt] = dev[half]
        core = [(w & f["active"] & (f["position"][:, 1] > 0.324) & (f["position"][:, 1] < 0.376)) for f in frames]
        flagged = np.mean([f["free_surface"][c].mean() for f, c in zip(frames, core) if c.any()])
        assert flagged < 0.005, (dt, flagged)
        assert np.max(np.abs(dev[half])) < level_bound, (dt, dev[half].min(), dev[half].max())
    n = min(len(d) for d in devs.values())
    stacked = np.array([d[:n] for d in devs.values()])
    spread = float(np.max(stacked.max(axis=0) - stacked.min(axis=0)))
    print(f"{option}, 10 mm: spread over dt 0.25 / 0.5 / 1 ms {spread:.4f}")
    assert spread < spread_bound, spread


@pytest.mark.parametrize("support", ["pore", "interior"])
def test_pore_support_reads_the_pore_lattice(ti_cpu, support):
    """Eq 31's density over the pore lattice's support (isph.ground_density_support: pore, _k_pore_density)
    in ground of porosity 0.25 holding water on its pore lattice (spacing 2 dx: 10 x 10 particles in a
    0.2 m block at dx 1 cm, exactly its pores): the support r_e eps^(-1/2) = 2 r_e is the free-water
    support scaled with the lattice, so away from the walls and the block's faces every particle reads
    eps rho_w (1e-9 relative). Every particle's reading is the sum over the water and wall particles
    within 2 r_e, the grid's cells searched two deep (against a sum over all particles, 1e-12).
    With `interior` (and free water over the ground) eq 31 takes that reading only where every water
    particle within the support has the particle's own porosity (against the same test over all
    particles): the top rows, whose support reaches the free water or the water on eq 32's ramp, take
    r_e; with `pore` every pore particle takes it."""
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene
    from taichi_sph.sph import kernels

    # with interior, free water over the ground (0.40-0.46 m) too, whose support reaches into the ground
    free = ", {min: [0.0, 0.4], max: [0.2, 0.46]}" if support == "interior" else ""
    cfg = load_config(ROOT / "configs" / "permeameter.yaml", overrides=[
        f"water=[{{min: [0.0, 0.2], max: [0.2, 0.4], porosity: 0.25}}{free}]", "tank.size=[0.2, 0.6]",
        "soil.regions=[{min: [0.0, 0.2], max: [0.2, 0.4], eps0: 0.25, d50: 0.01}]",
        f"isph.ground_density_support={support}"])
    scene = build_scene(cfg)
    assert np.allclose(scene.packing, 1.0)
    solver = ISPHSolver(cfg, scene)
    solver.initial_diagnostics()
    n = solver.n
    x, kind, eps = solver.x.to_numpy()[:n], solver.kind.to_numpy()[:n], solver.eps.to_numpy()[:n]
    rho = solver.rho_pore.to_numpy()[:n]
    pore = (kind == WATER) & (eps < 1.0)
    assert pore.sum() == 100
    re = kernels.SUPPORT_FACTOR * cfg.dx
    inner = pore & np.all((x > 2 * re) & (x < [0.2 - 2 * re, 0.4 - 2 * re]), axis=1) & (x[:, 1] > 0.2 + 2 * re)
    assert inner.sum() >= 4
    assert np.allclose(rho[inner], 0.25 * 1000.0, rtol=1e-9, atol=0.0), rho[inner]
    wet = solver.wet.to_numpy()[:n] == 1  # a dry wall (above the water) counts as air in every sum
    present = ((kind == WATER) | ((kind == WALL) & wet)) & (solver.active.to_numpy()[:n] != 0)
    for i in np.flatnonzero(pore):
        hp = min(eps[i] ** -0.5, 2.0) * 0.5 * re
        r = np.linalg.norm(x[present] - x[i], axis=1)
        share = np.where(kind[present] == WATER, eps[i] / eps[present], eps[i])
        wsum = np.sum(share * kernels.w_np(r, hp, 2) * (r < 2 * hp))
        assert rho[i] == pytest.approx(solver.mass * wsum / solver.kernel_sum, rel=1e-12)
    read = solver.pore_read.to_numpy()[:n]
    if support == "pore":
        assert np.all(read[pore] == 1)
        return
    water = (kind == WATER) & (solver.active.to_numpy()[:n] != 0)
    for i in np.flatnonzero(pore):
        hp = min(eps[i] ** -0.5, 2.0) * 0.5 * re
        near = water & (np.linalg.norm(x - x[i], axis=1) < 2 * hp)
        assert read[i] == int(np.all(np.abs(eps[near] - eps[i]) <= 1e-6)), (i, x[i], eps[near])
    assert np.all(read[inner] == 1)
    print(f"read over the pore support: {int(read[pore].sum())} of {int(pore.sum())}")
    assert 0 < read[pore].sum() < pore.sum()


@pytest.mark.xdist_group("permeameter_runs")  # one worker computes the shared runs once
def test_permeameter_core_is_not_free_surface(permeameter_runs):
    """The saturated plug's core (farther than r_e from its faces) holds no Dirichlet rows: the cone test
    in the ground flags none of it (time mean over frames) at dt 1 / 0.5 ms, against 26 % (dt 0.5 ms) with
    eq 34's count alone, and 0.1 / 0.9 % before the cone looked for air (a few particles at a time where
    the flow opened a gap for a step; each such row is a sink its neighbours flow into). Bound 0.5 %: one
    particle in a fifth of the frames."""
    for dt, (_, _, _, flagged, _, _) in permeameter_runs.items():
        assert flagged < 0.005, (dt, flagged)


@pytest.mark.xdist_group("permeameter_runs")  # one worker computes the shared runs once
def test_permeameter_core_holds_its_pore_volume(permeameter_runs):
    """While the water seeps through, the plug's core holds its pore volume of water: counted without a
    kernel (each particle a slab of the pore rows' spacing, its bulk volume dx^2 / eps0, over the core's
    area; permeameter_runs), time mean over 0.1-0.44 s, 1.007 / 1.017 at dt 1 / 0.5 ms (frames
    0.990-1.026 / 0.996-1.031; one thread). Counted by centres, as this test did before, 1.010 / 1.020
    (frames 0.95-1.08: a row of pore water is a tenth of the core). Before the shift's anti-pairing took
    a wall pair at the pore water's rest distance from the wall (docs/isph.md), by centres 0.994 / 1.003
    and, in a second one-thread run, 1.014 / 1.004 (slabs 1.014 / 1.002); 0.999 / 0.998 before pore water
    in drained ground joined the tension rule, 1.001 / 1.011 before the corrector took each particle's
    own wall pressure. With eq 34's count alone it held 1.17 / 1.07 at 0.5 / 0.25 ms (Dirichlet rows, sinks in
    the plug), with the cone and the correction inside the plug 1.06-1.09: water in excess of the pores
    seeps at fill x vD and drained the column early. Bound 2 % on the mean, 5 % on each frame (10 % when
    the test counted centres)."""
    for dt, (t, _, _, _, fill, _) in permeameter_runs.items():
        late = t >= 0.1
        assert abs(fill[late].mean() - 1.0) < 0.02, (dt, fill[late].mean())
        assert np.all(np.abs(fill[late] - 1.0) < 0.05), (dt, fill[late].min(), fill[late].max())


@pytest.mark.xdist_group("freefall_coarse")  # its run is shared with test_markers_stored_in_the_run_file
def test_freefall_coarse_volume_and_fraction_in_layer(freefall_coarse):
    """The seed's free fall (configs/freefall.yaml, variant coarse: dx 2 cm, 1000 water particles,
    the seed's dt 1 ms, alpha 0.01), run to 3.5 s, with the default surface test in the ground (the
    cone, air only from the air, the tension rule, no gradient correction inside saturated coarse
    ground; docs/isph.md).
    Measured on the 2-core CPU, one thread (two threads do not repeat bit for bit, and the scatter grows
    through the splash; with eq 34's count alone, the old default, three runs gave 0.427-0.463 s, 0.31-0.34,
    +0.14..+0.42 % and -4.4..-5.7 %); the numbers are those since the shift's anti-pairing takes a wall
    pair at the pore water's rest distance from the wall (2026-11-29, docs/isph.md; dt 0.9 / 1.1 ms read
    from frames every 10 ms). "Before" below is the code since the wall collision holds against every
    face of a corner (docs/isph.md, "Near-contact collisions"); before that, with the face the round-off
    chose, 0.365 s, 0.266, +0.27 % and 0.341 / 0.377 s, +0.24 / +0.41 % at dt 0.9 / 1.1 ms; before pore
    water in drained ground joined the tension rule 0.389 s, 0.278:
    - arrival at the layer bottom 0.363 s (0.365 / 0.340 s at dt 0.9 / 1.1 ms; before 0.402 s, 0.377 / 0.378
      s; seed 0.42 s at dx 1 cm, the 1D front of its equations 0.391 s; before drained pore water became a
      candidate of the cone test and the tension rule kept the air a particle had, 0.411 s, 0.343 / 0.358
      s): the lowest particle's,
      which scatters by the run; bound 0.3-0.6 s: a layer that does not drain or water that falls through
      it freely (0.2 m at g/eps) is far outside;
    - fraction of the water inside the layer (0.20 <= z <= 0.40) at that moment 0.291 (0.285 / 0.276;
      before 0.295, 0.277 / 0.273; before that 0.274, 0.275 / 0.272), seed "about eps0": bound
      |f - 0.3| < 0.1, the acceptance value (the
      layer is 10 spacings deep at 2 cm);
    - water volume measure (sum of m eps / <rho>, docs/output.md) against t = 0, averaged over 3.0-3.5 s,
      once the pool has settled: +0.23 % (+0.09 / +0.32 % at dt 0.9 / 1.1 ms; before +0.18 %, +0.22 /
      +0.55 %; before that +0.37 %, +0.13 / +0.42 %; before the tension rule in the ground +0.27 %,
      +0.47 / +0.27 %). Over 0.1-3.5 s it reads -2.26..+2.02 % (-1.50..+1.98 / -2.56..+2.22 %; before
      -2.09..+1.96 %, -1.55..+1.40 / -1.57..+2.17 %). Bound 1 %, the acceptance value. The cube's water fills the
      chamber under the layer exactly (0.2 m of each), so the pool's top meets the layer at 2.3-2.6 s:
      the free-surface rows (counted m / rho_w) fall from about 200 to 20 as the pool joins the layer's
      water, the pool reads 1-3 % below its rest density at 2.5 s, and the measure spikes to
      +2.0..+2.5 % (+2.0..+3.0 % before the collision change; +1.6..+2.6 % before the tension rule in
      the ground) before it settles by 3 s (docs/freefall.md).
      The window this test used before, the last 0.25 s of the shipped 2.5 s, straddled that spike:
      +0.95 % at dt 1 ms but +0.99 / +1.47 % at 0.9 / 1.1 ms before the tension rule in the ground,
      +1.52 % at 1 ms with it: a test that held at the one step. On the way the measure reads -3.5 % at
      0.04 s (the cube's bottom layer entering the ground; -3.4 / -3.6 % at dt 0.9 / 1.1 ms; before -3.6,
      -3.7 / -3.8 %) and stays within the range above after 0.1 s, the spike included (eq 34's count
      alone: -4.4..-5.7 % while the water passes the layer); bound 5 %, which a loss of the water
      entering the ground would exceed; the acceptance's 1 % at every frame is not met
      (docs/freefall.md): the entry dip is first order in dx (test_freefall_entry_dip_falls_with_the_spacing)."""
    out, r = freefall_coarse
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        water = rf.kind == 0
        zmin, frac = [], []
        for i in range(rf.n_frames):
            f = rf.frame(i)
            z = f["position"][water & f["active"]][:, -1]
            zmin.append(z.min())
            frac.append(np.mean((z >= 0.20) & (z <= 0.40)))
        t = rf.times
        d = rf.diagnostics()
    zmin, frac = np.array(zmin), np.array(frac)
    k = int(np.argmax(zmin < 0.20))
    assert k > 0, "the water never reached the bottom of the layer"
    s = (zmin[k - 1] - 0.20) / (zmin[k - 1] - zmin[k])
    arrival = t[k - 1] + s * (t[k] - t[k - 1])
    assert 0.3 < arrival < 0.6, arrival
    frac_at = frac[k - 1] + s * (frac[k] - frac[k - 1])
    assert abs(frac_at - 0.3) < 0.1, frac_at
    vol = d["water_volume"] / d["water_volume"][0] - 1.0
    assert d["time"][-1] > FREEFALL_COARSE_END - 1e-6
    settled = d["time"] >= FREEFALL_COARSE_END - 0.5
    assert abs(vol[settled].mean()) < 0.01, vol[settled].mean()
    assert np.max(np.abs(vol)) < 0.05, (vol.min(), vol.max())


@pytest.mark.long
@pytest.mark.xdist_group("freefall_coarse")  # reads the coarse free fall's run (fixture freefall_coarse)
def test_freefall_entry_dip_falls_with_the_spacing(freefall_coarse, run_cli, tmp_path):
    """The water volume measure (sum m eps / <rho>) dips while the cube's bottom row enters the ground:
    that one row, pressed to the lattice's spacing in plan, reads <rho> 1.5-1.6 x eps rho_w on the
    porosity's ramp (at 2 cm, 0.04 s: eps 0.36, <rho> 552 kg/m^3, 8 of its 100 particles free surface)
    until it has stretched along the flow to its pore spacing, and it is counted at about 0.62 of its
    volume. The water volume itself is conserved (the particles' mass is fixed), so the dip must vanish
    as dx -> 0, in proportion to the row's share of the water, dx / 0.2 m. Measured, lowest over the
    first 0.1 s (configs/freefall.yaml, eps0 0.3; the test reads the first 0.06 s): -3.57 / -2.28 / -1.23 % at dx 2 / 1 / 0.5 cm, dt 1 ms
    (-3.44 / -2.05 / -1.14 % at dt 0.5 ms): first order in dx, not in dt (docs/freefall.md, "The dip
    as the cube enters"). Since drained pore water is a candidate of the cone test, -3.71 / -2.26 % at
    2 / 1 cm (dt 1 ms), and since the shift's anti-pairing takes a wall pair at the pore water's rest
    distance from the wall (docs/isph.md) -3.51 / -2.21 %. Bounds: the dip at 1 cm below 0.7 of that at
    2 cm (measured 0.63; 0.61 and 0.64 before; a dip that did not shrink with the row's share would be
    1.0), and each within 10 % of its measured size above it (3.86 % and 2.43 %)."""
    coarse, r = freefall_coarse
    assert r.returncode == 0, r.stderr
    fine = tmp_path / "ff1.h5"
    r = run_cli("--config", "configs/freefall.yaml", "--set", "end_time=0.06", "--set", "output.every=0.06",
                "--out", fine, "--no-progress")
    assert r.returncode == 0, r.stderr
    dips = []
    for path in (coarse, fine):
        with RunFile(path) as rf:
            d = rf.diagnostics()
        early = d["time"] <= 0.06 + 1e-9  # the dip is at 0.042 / 0.026 s (2 / 1 cm)
        dips.append(float(np.min(d["water_volume"][early] / d["water_volume"][0] - 1.0)))
    print(f"entry dip: {dips[0]:+.4f} (dx 2 cm), {dips[1]:+.4f} (dx 1 cm)")
    d2, d1 = dips
    assert -0.0386 < d2 < 0 and -0.0243 < d1 < 0, dips
    assert abs(d1) < 0.7 * abs(d2), dips



def test_one_dimensional_front_reduces_to_its_limits():
    """porosity.penetration_front, the reference of the free fall's seepage, in its two limits: with no
    grains (eps 1: a = b = 0, Cr = 1) the column falls freely, z = g t^2 / 2; in fine sand (D50 0.5 mm) the
    front is quasi-steady, Green and Ampt's (1911) front without capillary suction: a vD + b vD^2 =
    (g / eps) (h + z) / z at every instant, dz/dt = vD / eps, h = h0 - eps z. Bounds: 1e-6 relative for
    the free fall (the ODE solver's tolerance); 1e-4 for the arrival in fine sand, where the balance's
    inertia lasts about 1 / a = 0.04 ms of the 27 s crossing (measured 1.5e-6)."""
    from scipy.integrate import solve_ivp

    from taichi_sph.isph.porosity import penetration_front, terminal_darcy_velocity

    z, arrival = penetration_front(0.2, 0.2, 1.0, 0.01)
    assert arrival == pytest.approx(np.sqrt(2 * 0.2 / G), rel=1e-6)
    assert z(0.1) == pytest.approx(0.5 * G * 0.01, rel=1e-6)

    eps, d50 = 0.4, 0.0005
    _, arrival = penetration_front(0.2, 0.2, eps, d50, t_end=3600.0)

    def rate(_t, y):
        zz = max(y[0], 1e-9)
        return [terminal_darcy_velocity(eps, 1.0e-6, d50, gradient=(0.2 - eps * zz + zz) / zz) / eps]

    def reached(_t, y):
        return y[0] - 0.2

    reached.terminal = True
    quasi = solve_ivp(rate, (0.0, 3600.0), [1e-6], events=reached, rtol=1e-10, atol=1e-12)
    print(f"fine sand: arrival {arrival:.2f} s, quasi-steady {quasi.t_events[0][0]:.2f} s")
    assert arrival == pytest.approx(quasi.t_events[0][0], rel=1e-4)


def test_water_body_arrival_is_the_front_arrival():
    """porosity.bulk_front_arrival, the free fall's arrival of the water body (the share of the water below
    the layer's top reaching eps0 depth / h0), read on the 1D front's own share eps0 z(t) / h0 sampled as a
    run's frames (every 10 ms) gives back the front's arrival (penetration_front) for each of the seed's
    porosities. Bound 1e-4 relative: linear interpolation between frames over a front that decelerates
    (measured 0.9e-6 / 1.5e-5 / 0.7e-6 for eps0 0.3 / 0.5 / 0.8). Before the share reaches it: nan."""
    from taichi_sph.isph.porosity import bulk_front_arrival, penetration_front

    for eps0 in (0.3, 0.5, 0.8):
        z, arrival = penetration_front(0.2, 0.2, eps0, 0.01)
        rate = eps0 * (z(arrival) - z(arrival - 1e-4)) / 1e-4 / 0.2  # the share's rate as the front arrives
        t = np.arange(0.0, arrival + 0.02, 0.01)
        share = [eps0 * z(tk) / 0.2 if tk <= arrival else eps0 + rate * (tk - arrival) for tk in t]
        assert bulk_front_arrival(t, share, eps0, 0.2, 0.2) == pytest.approx(arrival, rel=1e-4)
    assert np.isnan(bulk_front_arrival([0.0, 0.1], [0.0, 0.1], 0.3, 0.2, 0.2))


def test_slab_count_of_a_lattice_does_not_move_with_its_offset():
    """porosity.slab_count, the coarse free fall's count of the water in the layer's core (each particle a
    slab of the pore lattice's row spacing): rows at spacing a, shifted through a whole spacing across a
    core 3.5 rows tall (the free fall's at dx 2 cm), count (hi - lo) / a rows at every offset, as the
    volume they fill; a count of the centres moves between 3 and 4 rows. Bound 1e-12 (rounding); a row
    lying wholly inside counts 1, one wholly outside 0."""
    from taichi_sph.isph.porosity import slab_count

    a, lo = 0.03, 0.248
    hi = lo + 3.5 * a
    centres = set()
    for offset in np.linspace(0.0, a, 37):
        z = 0.2 + offset + a * np.arange(-2, 12)
        assert slab_count(z, lo, hi, a) == pytest.approx(3.5, abs=1e-12), offset
        centres.add(int(np.sum((z > lo) & (z < hi))))
    assert centres == {3, 4}
    assert slab_count([lo + 0.5 * a], lo, hi, a) == pytest.approx(1.0, abs=1e-12)
    assert slab_count([lo - 0.5 * a, hi + 0.5 * a], lo, hi, a) == 0.0


def _entered_against_front(path, eps0):
    """Largest deviation, over the frames up to the 1D front's arrival, of the share of the water below the
    layer's top (z < 0.40 m) from eps0 z(t) / h0, the water the 1D front of porosity.penetration_front
    has taken into the ground (h0 0.2 m over 0.2 m of D50 1 cm); and how many frames were compared."""
    from taichi_sph.isph.porosity import share_against_front

    with RunFile(path) as rf:
        water = rf.kind == 0

        def share(i):
            f = rf.frame(i)
            return float(np.mean(f["position"][water & f["active"]][:, -1] < 0.40))

        dev, _, frames = share_against_front(rf.times, share, 0.2, 0.2, eps0, 0.01)
    return dev, frames


@pytest.mark.long
@pytest.mark.xdist_group("freefall_coarse")  # reads the coarse free fall's run (fixture freefall_coarse)
def test_freefall_coarse_seeps_in_as_the_one_dimensional_front(freefall_coarse, run_cli, tmp_path):
    """The water the coarse free fall (dx 2 cm) takes into the layer against the 1D front of the seed's own
    equations (porosity.penetration_front: the column and the saturated ground behind a sharp front move
    together, (h + Cr z) dvD/dt = g (h + z) - eps z (a vD + b vD^2), atmospheric pressure at the top and at
    the front), up to the front's arrival at the layer's bottom (0.391 / 0.324 / 0.250 s for eps0 0.3 /
    0.5 / 0.8; the seed reports 0.42 / 0.34 / 0.26 s), at dt 1 and 0.5 ms. That front has no walls and no
    spread, and at 2 cm one row of the cube is 0.1 of the water. The test runs the porosities at the two
    ends, eps0 0.3 and 0.8. Measured, largest deviation of the share below the layer's top at dt 1 / 0.5
    ms, frames every 10 ms (the fixture's every 20 ms): eps0 0.3 +0.038 / +0.051, eps0 0.8 +0.048 / +0.065
    (before the shift's anti-pairing took a wall pair at the pore water's rest distance from the wall,
    docs/isph.md: -0.035 / +0.051 and +0.048 / +0.061; frames every 5 ms: +0.051 / +0.058 and -0.051 / +0.061; eps0 0.5, not run here, +0.062 / +0.052; at
    the seed's dx 1 cm at most 0.034; docs/freefall.md, "Against the one-dimensional front"). The positive
    peak comes at 0.04 s, when the cube's bottom row has crossed the layer's top as one and the front has
    taken in 0.05 of the water: the count of particle centres moves by rows. Later the share lags the
    front by up to 0.053, the walls' friction. Bound 0.07: near the measured 0.065, and below the 0.1 of a
    row that a front one row early or late would give. Before drained pore water became a candidate of
    the cone test (isph.ground_drained_candidate)
    eps0 0.8 read +0.065 / +0.167: its front, undetected as it entered the ground as a sheet, was pulled
    through the layer by eq 31's term, the more so the smaller the step (docs/freefall.md, "Small fixed
    steps")."""
    coarse, r = freefall_coarse
    assert r.returncode == 0, r.stderr
    runs = {(0.3, 0.001): coarse}
    for eps0, dt in ((0.3, 0.0005), (0.8, 0.001), (0.8, 0.0005)):
        out = tmp_path / f"ff_{eps0}_{dt}.h5"
        end = {0.3: 0.40, 0.8: 0.26}[eps0]  # past the 1D front's arrival
        r = run_cli("--config", "configs/freefall.yaml", "--variant", "coarse", "--set", f"dt={dt}",
                    "--set", f"soil.regions.0.eps0={eps0}", "--set", f"end_time={end}", "--set",
                    "output.every=0.01", "--out", out, "--no-progress")
        assert r.returncode == 0, r.stderr
        runs[(eps0, dt)] = out
    devs = {}
    for (eps0, dt), path in runs.items():
        devs[(eps0, dt)], frames = _entered_against_front(path, eps0)
        assert frames > 12, frames
    print("entered - 1D front:", {k: round(v, 4) for k, v in devs.items()})
    assert all(abs(v) < 0.07 for v in devs.values()), devs


def _narrow_freefall(eps0):
    """configs/freefall.yaml, variant coarse, in a tank of 0.1 x 0.1 m: a 0.1 x 0.1 x 0.2 m block of 250
    water particles over the 0.2 m layer of porosity eps0 (D50 1 cm). Returns (cfg, scene, solver), the
    solver's initial diagnostics taken."""
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    narrow = ["tank.size=[0.1, 0.1, 0.7]", "water=[{min: [0.0, 0.0, 0.40], max: [0.10, 0.10, 0.60]}]",
              f"soil.regions=[{{min: [0.0, 0.0, 0.20], max: [0.10, 0.10, 0.40], eps0: {eps0}, d50: 0.01}}]"]
    cfg = load_config(ROOT / "configs" / "freefall.yaml", variant="coarse", overrides=narrow)
    scene = build_scene(cfg)
    solver = ISPHSolver(cfg, scene)
    solver.initial_diagnostics()
    return cfg, scene, solver


def test_drained_gravel_holds_no_water_in_suction(ti_cpu):
    """The seed's free fall through its most open layer (configs/freefall.yaml, variant coarse, eps0 0.8,
    D50 1 cm) in a tank of 0.1 x 0.1 m (a 0.1 x 0.1 x 0.2 m block of 250 water particles over the 0.2 m
    layer, to keep it small), 1 s, at dt 0.9 and 1.1 ms: the water in the layer (0.20 <= z <= 0.40) once
    the block has passed (its front reaches the layer's bottom at about a quarter of a second). Gravel this coarse holds no water by
    suction: Hazen's capillary rise C / (e D10), C = 0.1-0.5 cm^2, is under a centimetre at void ratio
    e = 4 for D10 of a few millimetres, at most 4 % of this water over the layer's 0.2 m. Measured (one
    thread, in-process): 0.048 / 0.032 of the water in the layer at 1 s (0.068 / 0.056 before the shift's
    anti-pairing took a wall pair at the pore water's rest distance, docs/isph.md; 0.076 / 0.060 before the wall
    collision held against every face of a corner, docs/isph.md); before pore water in drained
    ground joined the tension rule (docs/isph.md, "Air into drained pores") 0.544 / 0.176, the rest
    hanging in the layer's lower part under suction. Bound 0.12: the capillary 4 % and the drops still
    in transit, which scatter by the run (0.06-0.10 over 0.8-1.0 s in runs with frames)."""
    _, scene, solver = _narrow_freefall(0.8)
    start = solver.state()
    water = scene.kind == 0
    for dt in (0.0009, 0.0011):
        solver.load_state(start)
        for _ in range(round(1.0 / dt)):
            solver.step(dt)
        f = solver.fields_by_id()
        z = f["position"][water & f["active"]][:, -1]
        in_layer = float(np.mean((z >= 0.20) & (z <= 0.40)))
        print(f"dt {dt}: water in the layer at 1 s {in_layer:.3f}")
        assert in_layer < 0.12, (dt, in_layer)


def test_freefall_does_not_follow_round_off_in_the_tank_corners(ti_cpu):
    """The seed's free fall (variant coarse) in a tank of 0.1 x 0.1 m (the block of the test above over the
    shipped eps0 0.3 layer), 60 ms, from the lattice and from the lattice moved by 1e-12 dx (uniform per
    particle and axis): the block enters the ground at 35 ms, and the two runs must stay as near as
    round-off growth takes them. The wall collision once took the nearest wall particle only: a particle in
    the tank's corner column is as near to two faces, so round-off chose the face, and the full-width free
    fall's runs parted by 1.2e-2 dx within the step of 35 ms (CPU against CUDA likewise, docs/performance.md
    "Fourth round"). Measured since every face is taken: 1.3e-11 dx (3.7e-11 dx before the shift's
    anti-pairing took a wall pair at the pore water's rest distance, docs/isph.md; 1.1e-3 dx with the
    nearest face only); bound 1e-6 dx, where one flipped decision moves a particle by 1e-3 dx or more."""
    cfg, _, solver = _narrow_freefall(0.3)
    start = solver.state()
    moved = dict(start)
    water = start["kind"] == 0
    rng = np.random.default_rng(1)
    moved["x"] = start["x"] + np.where(water[:, None], rng.uniform(-1, 1, start["x"].shape), 0.0) * 1e-12 * cfg.dx
    ends = []
    for state in (start, moved):
        solver.load_state(state)
        for _ in range(60):
            solver.step(0.001)
        ends.append(solver.fields_by_id()["position"])
    apart = float(np.abs(ends[0] - ends[1]).max()) / cfg.dx
    print(f"largest difference after 60 ms: {apart:.2e} dx")
    assert apart < 1e-6, apart


def test_lone_particles_in_a_corner_of_the_ground_are_free_surface(ti_cpu):
    """Two water particles, one above the other, in a vertical edge of a tank filled with ground of
    eps0 0.8 (3D), beside a pool resting in the ground. Eq 34 in the ground holds the count against
    N_surf N(eps) / N(1) = 48 x 32 / 56 = 27.4 at eps 0.8 (a lattice shell has left the support).
    Walls counted as eps_i = 0.8 of a neighbour each came to about that alone and kept such particles
    out of the free surface: their PPE rows (one water neighbour against the walls' divergence) gave
    pressures of 100 kPa and kicks of 850 m/s in the seed's free fall at dx 1 cm, eps0 0.8. Counted as
    N(eps) / N(1) each, the pair is free (P = rho_w g dx / 2) and stays slow, while the pool's
    particles below its top two rows, against the floor and the walls, are not free."""
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    dx = 0.01
    cfg = load_config(data={
        "mode": "isph", "dim": 3, "dx": dx, "end_time": 0.01, "dt": 0.001, "tank": {"size": [0.12, 0.12, 0.2]},
        "water": [{"min": [0.0, 0.0, 0.127], "max": [dx, dx, 0.147]},
                  {"min": [0.04, 0.0, 0.0], "max": [0.12, 0.12, 0.08]}],
        "soil": {"regions": [{"min": [0.0, 0.0, 0.0], "max": [0.12, 0.12, 0.2], "eps0": 0.8, "d50": 0.01}]}})
    solver = ISPHSolver(cfg, build_scene(cfg))
    solver.initial_diagnostics()
    for _ in range(10):
        solver.step(cfg.dt)
    kind = solver.kind.to_numpy()
    x, free = solver.x.to_numpy(), solver.free.to_numpy()
    pair = (kind == 0) & (x[:, 0] < 0.03)
    pool = (kind == 0) & (x[:, 0] >= 0.03)
    assert pair.sum() == 2 and pool.sum() == 8 * 12 * 8
    assert np.all(free[pair] == 1), x[pair]
    # in 10 steps of free fall at g / eps the pair reaches 0.12 m/s; a PPE row held against the walls
    # kicked such particles to metres per second within a few steps
    v = np.linalg.norm(solver.v.to_numpy()[kind == 0], axis=1)
    assert v.max() < 0.3, v.max()
    deep = pool & (x[:, 2] < 0.08 - 2.5 * dx)
    assert deep.sum() > 300 and np.all(free[deep] == 0)


def test_a_gap_opened_inside_saturated_ground_is_not_free_surface(ti_cpu):
    """Air reaches an empty cone only from the air. Saturated ground (2D, eps0 0.4, dx 5 mm, the pore
    water on its lattice, 1.58 dx apart), open to the air at its top; after a step, the pore water within
    1.2 pore spacings of its centre is taken out, which leaves a gap closed on every side by water. Its
    rim's cones are empty within the support, and the cone test alone flagged 2 of them free surface
    (Dirichlet rows at the atmosphere's pressure inside saturated ground: sinks, which the flow filled and
    the projection emptied in one step when the gap closed; 10-20 kPa spikes in the permeameter's plug at
    dt 0.25 ms). No air can reach the gap, so no particle there is a surface; the ground's top, open to
    the air, stays free surface in every column."""
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    dx, eps0 = 0.005, 0.4
    cfg = load_config(data={
        "mode": "isph", "dim": 2, "dx": dx, "end_time": 0.01, "dt": 0.0005, "tank": {"size": [0.1, 0.15]},
        "water": [{"min": [0.0, 0.0], "max": [0.1, 0.1], "porosity": eps0}],
        "soil": {"regions": [{"min": [0.0, 0.0], "max": [0.1, 0.1], "eps0": eps0, "d50": 0.01}]}})
    solver = ISPHSolver(cfg, build_scene(cfg))
    solver.initial_diagnostics()
    solver.step(cfg.dt)
    centre, pore = np.array([0.05, 0.05]), dx / np.sqrt(eps0)
    x, kind = solver.x.to_numpy(), solver.kind.to_numpy()
    gap = (kind == 0) & (np.linalg.norm(x - centre, axis=1) < 1.2 * pore)
    active = solver.active.to_numpy()
    active[gap] = 0
    solver.active.from_numpy(active)
    for _ in range(3):
        solver.step(cfg.dt)
        # the particle arrays are put in cell order every step: read them together
        x, free, kind = solver.x.to_numpy(), solver.free.to_numpy(), solver.kind.to_numpy()
        water = (kind == 0) & (solver.active.to_numpy() != 0)
        rim = water & (np.linalg.norm(x - centre, axis=1) < 2.5 * dx)
        top = water & (x[:, 1] > 0.1 - pore)
        assert gap.sum() == 6 and rim.sum() >= 2
        assert np.all(free[water & (x[:, 1] < 0.1 - 2 * pore)] == 0)
        assert top.sum() == 12 and np.all(free[top] == 1)
