"""Seepage failure (seed 002 sections 3.4-3.5): the levee of configs/embankment.yaml (stage 1 at rest, the
landside toe yielding first, a dry levee wetting), heave behind the sheet pile of configs/sheetpile.yaml,
and the flow-net reference for that heave. Full runs: tools/seepage_failure.py, docs/levee.md and
docs/sheetpile.md."""

import numpy as np
import pytest

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.wcsph.failure import yield_sequence
from taichi_sph.wcsph.flownet import harr_prism_ratio, prism_ratio

from .conftest import cli

SOIL = 2


def test_flow_net_matches_the_conformal_map_of_a_pile_in_a_deep_bed():
    """The finite-difference flow net (taichi_sph/wcsph/flownet.py) that gives Terzaghi's heave head for
    configs/sheetpile.yaml, against the exact head of a thin pile in a bed of infinite depth (conformal map,
    Harr 1962): the mean excess head on the base of the prism D deep and D / 2 wide is 0.354 dH. The
    finite differences model a pile two cells thick, so the pile thins with the grid: D / 40 and D / 80
    give 0.3359 and 0.3433 (bed 3 D deep, 6 D long; 6 D deep gives 0.3369 and 0.3442), first order, and
    the extrapolation 2 x 0.3433 - 0.3359 = 0.3507 lies 0.9 % below the exact value (the bed's finite depth
    takes 0.2 % of it). Bound 1.5 %."""
    exact = harr_prism_ratio()
    assert abs(exact - 0.354) < 5e-4  # the map itself: 0.35396
    coarse = prism_ratio(0.6, 0.3, 0.1, 0.005, 0.0025)
    fine = prism_ratio(0.6, 0.3, 0.1, 0.0025, 0.00125)
    assert coarse < fine < exact  # converging from below as the pile thins
    assert abs((2 * fine - coarse) / exact - 1) < 0.015, (coarse, fine, exact)


def _soil_end_state(path):
    """Largest soil displacement between the first and the last frame, and the largest plastic strain."""
    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        x0 = rf.field("position", 0)[soil]
        x1 = rf.field("position", rf.n_frames - 1)[soil]
        eps = rf.field("plastic_strain", rf.n_frames - 1)[soil]
    return float(np.linalg.norm(x1 - x0, axis=1).max()), float(eps.max())


@pytest.fixture(scope="module")
def levee_stage1_coarse(tmp_path_factory):
    """configs/embankment.yaml, variant geostatic (stage 1) at dx 0.02, run once for the tests marked
    xdist_group("levee_stage1"): its run file and the CLI's CompletedProcess."""
    out = tmp_path_factory.mktemp("levee") / "s1.h5"
    return out, cli("--config", "configs/embankment.yaml", "--variant", "geostatic", "--set", "dx=0.02", "--out", out,
                    "--no-progress")


@pytest.mark.parametrize("dx", [0.01, pytest.param(0.02, marks=pytest.mark.xdist_group("levee_stage1"))])
def test_levee_stage1_stands(run_cli, tmp_path, dx, request):
    """configs/embankment.yaml, stage 1 (`geostatic`: the river at 0.10 m, the pore water below a phreatic
    line inside the levee, the K0 start, damping 400 1/s, 0.3 s). The acceptance: largest soil
    displacement below 1 mm and no particle beyond a plastic strain of 1e-3. Measured: 0.029 mm and
    0.81e-3 at dx 0.01, 0.042 mm and 0.97e-3 at dx 0.02 (the largest strains in the crest's core, where
    the K0 start leaves the mound's top short of lateral support). Bounds: displacement 0.1 mm (a tenth of
    the acceptance's), plastic strain 1e-3 (the acceptance's). The stage that follows without damping
    (stage 2 with the river held, the first 0.5 s at dx 0.02) must stay at rest too: displacement below
    0.02 mm (measured 0.006 mm) and the largest plastic strain grown by less than 5e-4 (measured 1.0e-4,
    in the crest's core; a slip would take it past 1e-2): the damping does not hide a levee that would not
    stand."""
    if dx == 0.02:  # shared with the first-yield test
        s1, r = request.getfixturevalue("levee_stage1_coarse")
    else:
        s1 = tmp_path / "s1.h5"
        r = run_cli("--config", "configs/embankment.yaml", "--variant", "geostatic", "--set", f"dx={dx}",
                    "--out", s1, "--no-progress")
    assert r.returncode == 0, r.stderr
    disp, eps = _soil_end_state(s1)
    assert disp < 1e-4 and eps < 1e-3, (dx, disp, eps)
    if dx == 0.02:
        s2 = tmp_path / "s2.h5"
        r = run_cli("--config", "configs/embankment.yaml", "--set", f"dx={dx}", "--set", "end_time=0.5",
                    "--set", "obstacles.0.motion.velocity=[0.0,0.0]",
                    "--set", f"wcsph.soil.start_from.run={s1}", "--out", s2, "--no-progress")
        assert r.returncode == 0, r.stderr
        disp2, eps2 = _soil_end_state(s2)
        assert disp2 < 2e-5 and eps2 - eps < 5e-4, (disp2, eps, eps2)


def _sheetpile_heave(run_cli, tmp_path, head, name, end=1.5):
    """configs/sheetpile.yaml, variant `coarse` (dx 0.02) from its K0 start (no stage 1) with the upstream
    side held at `head` m and the downstream side at 0.24 m (the piston still), `end` s: the rise of the sand
    surface over the width D beside the pile (probe heave) from 0.5 s on, and the largest rise."""
    out = tmp_path / f"{name}.h5"
    water = (f"water=[{{min: [0.06, 0.0], max: [0.84, {head}]}}, {{min: [0.84, 0.0], max: [1.26, 0.24]}}]")
    r = run_cli("--config", "configs/sheetpile.yaml", "--variant", "coarse", "--set", f"end_time={end}",
                "--set", "wcsph.soil.start_from=null", "--set", "obstacles.0.motion=null", "--set", water,
                "--set", "wcsph.water.sound_speed=34.0",  # 10 x the free fall from the upstream side's 0.58 m
                "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    with RunFile(out) as rf:
        t, level = rf.probes()["heave"]
        tu, up = rf.probes()["h_upstream"]
        td, down = rf.probes()["h_downstream"]
    lift = np.asarray(level) - level[0]
    dh = float(np.mean(np.asarray(up)[tu > 0.5]) - np.mean(np.asarray(down)[td > 0.5]))
    return dh, float(lift[np.asarray(t) > 0.5].max()), float(lift[-1])


@pytest.mark.long
def test_sheetpile_heaves_within_20_percent_of_terzaghi(run_cli, tmp_path):
    """Terzaghi's prism criterion for the coarse sheet pile (dx 0.02, pile 6 cm thick, D = 0.06 m, bed
    0.20 m): the flow net gives a mean excess head of 0.209 dH on the base of the prism D deep and D / 2
    wide, so the sand beside the pile heaves at dH_c = 0.99 D / 0.209 = 0.284 m. Held at 0.8 dH_c the
    surface over the width D beside the pile must not rise by 1 mm (the acceptance's heave), held at
    1.2 dH_c it must (the acceptance's 20 %). Measured (head differences as the probes read them from
    0.5 s): dH 0.226 m, largest rise 0.01 mm to 2 s (0.005 mm to 1.5 s); dH 0.339 m, 3.8 / 5.2 / 6.5 mm
    at 1 / 1.5 / 2 s (still rising). The runs stop at 1.5 s, where the heave has passed 1 mm five times
    over. docs/sheetpile.md has the full rise at dx 0.01 and 0.02."""
    dh_c = 0.99 * 0.06 / prism_ratio(0.54, 0.2, 0.06, 0.06, 0.0025, at=0.12)
    assert abs(dh_c - 0.284) < 0.002
    below = _sheetpile_heave(run_cli, tmp_path, round(0.24 + 0.8 * dh_c, 3), "below")
    above = _sheetpile_heave(run_cli, tmp_path, round(0.24 + 1.2 * dh_c, 3), "above")
    assert below[1] < 1e-3, below
    assert above[2] > 1e-3, above


@pytest.mark.xdist_group("levee_stage1")  # stage 1 is the shared run (fixture levee_stage1_coarse)
def test_levee_first_yield_at_the_landside_toe(run_cli, tmp_path, levee_stage1_coarse):
    """configs/embankment.yaml at dx 0.02, shortened: stage 1 as shipped, stage 2 with k five times the
    shipped 3 cm/s and the piston five times as fast (Darcy's law makes the seepage's time scale 1 / k, and
    the drag of the river's flow on the riverside slope, (g / k) times its speed, keeps its size), 5.5 s
    in place of ~27 s. The acceptance: the first particle past a plastic strain of 1e-2 lies within 3 dx
    of the landside toe (2.26, 0). The first frame (every 0.25 s) with a particle past 1e-2 holds a few
    particles at once on the lower landside slope; the most strained of them is the first. Measured: at
    4.75 s, three particles, (2.13, 0.05), (2.21, 0.01) and (2.23, 0.01), the most strained (2.23, 0.01),
    1.6 dx from the toe; with the time step halved (timestep.cfl 0.125) the same frame, particles and
    strains' order (the full run at the shipped k: 16.5 s, the same particle; dx 0.01: 11.0 s, (2.245,
    0.005), 1.6 dx; docs/levee.md); nothing on the riverside slope or the crest. At the physical c_v
    (the water's default sound speed, with eq 36 at the flow's 17.2 m/s and density diffusion 0.1 in
    either form, the first the defaults; 9x the steps, not run here) the same frame and particles yield first (docs/levee.md, "The sequence at the
    physical c_v"). Bound 3 dx: the acceptance."""
    (s1, r), s2 = levee_stage1_coarse, tmp_path / "s2.h5"
    assert r.returncode == 0, r.stderr
    r = run_cli("--config", "configs/embankment.yaml", "--set", "dx=0.02", "--set", "end_time=5.5",
                "--set", "output.every=0.25", "--set", "wcsph.soil.permeability=0.15",
                "--set", "obstacles.0.motion.velocity=[0.06,0.0]", "--set", "obstacles.0.motion.ramp=0.4",
                "--set", f"wcsph.soil.start_from.run={s1}", "--out", s2, "--no-progress")
    assert r.returncode == 0, r.stderr
    seq = yield_sequence(str(s2), 1e-2)
    first = seq["first"]
    assert first is not None, "no particle yielded"
    toe = np.array([2.26, 0.0])
    assert np.linalg.norm(np.asarray(first["x0_max"]) - toe) < 3 * 0.02, first
    assert all(x > 1.885 for x, _ in first["x0"]), first  # all on the landside slope


def _soil_moved(path, t):
    """The soil's largest displacement from the first frame (mm) and the number of soil particles past a
    plastic strain of 1e-2, in the frame nearest to t."""
    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        k = int(np.argmin(np.abs(np.asarray(rf.times, float) - t)))
        x0 = np.asarray(rf.field("position", 0), float)[soil]
        x = np.asarray(rf.field("position", k), float)[soil]
        eps = np.asarray(rf.field("plastic_strain", k), float)[soil]
    return 1e3 * float(np.linalg.norm(x - x0, axis=1).max()), int(np.count_nonzero(eps > 1e-2))


def _dry_front(path):
    """The dry levee's wetting front (failure.wetting_front) and the Boussinesq front for a sand of the test's
    permeability, 0.15 m/s, and S = n = 0.4, both per frame, from the river level the probe reads."""
    from taichi_sph.wcsph.dupuit import boussinesq_front
    from taichi_sph.wcsph.failure import wetting_front

    wf = wetting_front(str(path), 0.02, 1.26)
    t, front = np.asarray(wf["time"]), np.asarray(wf["front"])
    with RunFile(path) as rf:
        tr, hr = (np.asarray(v, float) for v in rf.probes()["river"])
    integral = np.interp(t, tr, np.concatenate([[0.0], np.cumsum(0.5 * (hr[1:] + hr[:-1]) * np.diff(tr))]))
    return t, front, boussinesq_front(0.15, 0.4, 1.0, integral)  # 1.62 sqrt(k integral(H dt) / S)


@pytest.mark.long
def test_dry_levee_wetting_front_follows_boussinesq(run_cli, tmp_path):
    """configs/embankment.yaml `dry` (its pore water at its own volume, `wcsph.soil.pore_water:
    pore_volume`, with density diffusion 0.1) at dx 0.02, shortened as the first-yield test: k five times
    the shipped, 0.15 m/s (the Boussinesq front's time scale is 1 / k), 4 s for the shipped k's 20 s: the
    river (0.12 m, falling to
    0.108 m as the levee takes in water) against the dry levee. The reference is the Boussinesq solution
    for a sand of this permeability, x_f = 1.62 sqrt(k integral(H dt) / S) with the river level H(t) the
    probe reads and the drainable porosity S = n = 0.4 (dry sand, no capillarity); the advance is taken
    from 0.4 s (k t = 0.06 m), so the entry's place on the sloping face drops out.
    Measured against S = n: -19.5 % at 2 s, -19.2 % at 2.2 s, -17.7 % at 4 s (before the soil took its
    pore-pressure force from the water's own pressure sums, -19.8 / -19.7 / -17.7 %, and the same to 0.1 mm
    with timestep.cfl 0.125, 53,364 steps against 30,269). Bound 22 % over 2-4 s, the
    largest measured plus 2 points; the acceptance's 20 % holds here and in the full runs at the shipped k
    (-13..-14 % at dx 0.02 over 8-20 s, docs/levee.md), this 5x k reading 4-6 points lower than the
    shipped k at the same k t (the front is a function of k t within 1.5 dx for k 1.5-6 cm/s, not beyond;
    docs/levee.md, "The front against the permeability"). Without the density diffusion the front read
    -22.6 / -20.0 % at 2 / 4 s, and pore water running ahead through the dry pores reached 3.4 kPa and
    yielded the crest. With full_volume (pore water filling the mixture's volume, storage 1) the same case
    read -34 / -37 %, the storage's sqrt(n). Before ~2 s the wedge under the sloping face is still
    filling. The advance is slower than linear: checked as a speed over 2.2-4 s below that over 0.4-2.2 s
    (x_f = a + b t^p over the full runs: p = 0.49 / 0.53 at dx 0.02 / 0.01; Boussinesq 0.5).
    The sound speed is a knob the front must not follow: the same case at the water's default sound
    speed (K_f = 40 n M, 222 m/s, the pore water's c0 / sqrt(n) = 351 m/s: the physical c_v, 7.7x the
    steps), where eq 36 takes the flow's sound speed (17.16 m/s) and the density diffusion is 0.1 in its
    gradient form by default, advances 0.1325 m from 0.4 s to 1.4 s against 0.1401 m at the pinned
    17.2 m/s. Bound: half a particle spacing, 0.01 m (full_volume: 0.131 against 0.130 m; with eq 36 at
    the raised c0, the default before, 0.105 m, 0.025 m short, which this test catches).
    Nor must the skeleton follow it. The riverside slope (16 deg against a friction angle of 30 deg)
    stands, wet or dry; the sudden river yields a few particles of its surface. At 1.4 s the soil has
    moved at most 0.92 mm at the physical c_v against 0.81 mm pinned, with 17 against 15 particles past a
    plastic strain of 1e-2. When the soil took its pore-pressure force from its own difference-form
    gradient of the Shepard pore pressure, the stiff pore water drove it: 13 mm and 175 of 208 particles
    by 1.4 s, all 208 and 51 mm by 4 s (docs/biot.md, "Pore water at its own volume"). Bounds: 0.2 mm and
    5 particles above the pinned run, about twice the measured differences."""
    s1, s2, s3 = tmp_path / "d1.h5", tmp_path / "d2.h5", tmp_path / "d3.h5"
    r = run_cli("--config", "configs/embankment.yaml", "--variant", "dry_geostatic", "--set", "dx=0.02",
                "--out", s1, "--no-progress")
    assert r.returncode == 0, r.stderr
    stage2 = ("--config", "configs/embankment.yaml", "--variant", "dry", "--set", "dx=0.02",
              "--set", "output.every=0.1", "--set", "wcsph.soil.permeability=0.15",
              "--set", f"wcsph.soil.start_from.run={s1}", "--set", "probes.1.box.max=[2.76, 0.03]", "--no-progress")
    r = run_cli(*stage2, "--set", "end_time=4.0", "--out", s2)
    assert r.returncode == 0, r.stderr
    t, front, ref = _dry_front(s2)
    # the config's probe `front` (its floor band set to 1.5 dx here) reads the same foot at its samples,
    # which fall on steps the frames also took (both at the first step at or after their multiples);
    # at t = 0 no water is in the soil yet and the probe reads the river's edge on the floor (1.35 m)
    with RunFile(s2) as rf:
        tp, fp = (np.asarray(v, float) for v in rf.probes()["front"])
    _, kf, kp = np.intersect1d(np.round(t, 9), np.round(tp, 9), return_indices=True)
    assert len(kp) == 9, tp  # 0, 0.5, ..., 4 s
    assert np.array_equal(front[kf[1:]], fp[kp[1:]]), (front[kf], fp[kp])
    k0 = int(np.argmin(np.abs(t - 0.4)))
    late = t >= 2.0 - 1e-9
    err = (front[late] - front[k0]) / (ref[late] - ref[k0]) - 1
    assert np.all(np.abs(err) < 0.22), err
    # slower than linear: the speed over the second half of the window is below that of the first half
    mid = int(np.argmin(np.abs(t - 2.2)))
    assert (front[-1] - front[mid]) / (t[-1] - t[mid]) < (front[mid] - front[k0]) / (t[mid] - t[k0])
    # the physical c_v (the water's default sound speed, and with it the defaults of eq 36's speed and the
    # density diffusion): the same advance to 1.4 s within half a particle spacing
    r = run_cli(*stage2, "--set", "end_time=1.4", "--set", "wcsph.water.sound_speed=null", "--out", s3)
    assert r.returncode == 0, r.stderr
    t3, front3, _ = _dry_front(s3)
    k3, m3 = int(np.argmin(np.abs(t3 - 0.4))), int(np.argmin(np.abs(t3 - 1.4)))
    m = int(np.argmin(np.abs(t - 1.4)))
    adv, adv3 = front[m] - front[k0], front3[m3] - front3[k3]
    assert abs(adv3 - adv) < 0.01, (adv, adv3)
    # the skeleton at 1.4 s: largest displacement (mm) and particles past 1e-2, at both sound speeds
    (d2, y2), (d3, y3) = _soil_moved(s2, 1.4), _soil_moved(s3, 1.4)
    assert d3 < d2 + 0.2 and y3 <= y2 + 5, (d2, y2, d3, y3)
