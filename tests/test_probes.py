"""Probes (taichi_sph/probes.py) on particle lattices with known answers, their sampling times, and
their two records: /probes/<name> in the run file and <run>.probes.csv (bit-equal values)."""

import numpy as np
import pytest

from taichi_sph.config import load_config
from taichi_sph.io.hdf5 import RunFile, RunWriter
from taichi_sph.probes import (
    ProbeRecorder,
    ProbeSet,
    mean_velocity_in_box,
    pressure_at,
    surge_front,
    water_level,
    water_volume_in_box,
)

RHO, G = 1000.0, 9.81
DX = 0.02
L, H = 0.4, 0.3  # water block [0, L] x [0, H] in a tank of width L with 3 wall layers


def _lattice(lo, hi, dx=DX):
    axes = [np.arange(a + dx / 2, b - 1e-12, dx) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(lo))


def _tank_2d(velocity=(0.0, 0.0), extra_water=None):
    water = _lattice([0, 0], [L, H])
    if extra_water is not None:
        water = np.concatenate([water, extra_water])
    wall = np.concatenate([_lattice([-3 * DX, -3 * DX], [L + 3 * DX, 0]), _lattice([-3 * DX, 0], [0, L]),
                           _lattice([L, 0], [L + 3 * DX, L])])
    pos = np.concatenate([water, wall])
    kind = np.r_[np.zeros(len(water)), np.ones(len(wall))].astype(np.int8)
    vel = np.zeros_like(pos)
    vel[kind == 0] = velocity
    return {"position": pos, "velocity": vel, "pressure": RHO * G * (H - pos[:, 1]), "kind": kind,
            "active": np.ones(len(pos), bool), "volume": np.full(len(pos), DX * DX)}


def test_pressure_probe_interpolates_a_hydrostatic_field():
    arrays = _tank_2d()
    # on a lattice site the full symmetric support reproduces a linear field to round-off
    assert pressure_at([0.21, 0.11], arrays, DX) == pytest.approx(RHO * G * (H - 0.11), rel=1e-12)
    # between sites the Shepard sum reads the field at the weighted centroid of the neighbours, which on a
    # lattice with this kernel lies within 1e-3 dx of the point (measured 4e-4 dx)
    p = pressure_at([0.213, 0.1234], arrays, DX)
    assert abs(p - RHO * G * (H - 0.1234)) < 1e-3 * RHO * G * DX
    # on the floor the support is one-sided: the gauge reads the pressure 0.5-0.7 dx up in the water
    p_floor = pressure_at([0.2, 0.0], arrays, DX)
    assert 0.5 * RHO * G * DX < RHO * G * H - p_floor < 0.7 * RHO * G * DX
    # a dry gauge (no water within the support) reads the atmosphere
    assert pressure_at([0.2, H + 2.5 * DX], arrays, DX) == 0.0


def test_water_level_is_the_surface_also_next_to_walls_and_ignores_droplets():
    # a lone particle 3 dx above the surface: its water fraction peaks at 0.32 < 0.5, so it is no surface
    droplet = np.array([[0.2 + DX / 2, H + 3 * DX]])
    arrays = _tank_2d(extra_water=droplet)
    # the fraction of a flat lattice surface crosses 0.5 at the block's top; measured within 0.004 dx at
    # mid-tank, off-lattice positions and a quarter dx from a wall (the wall correction of the fraction),
    # tolerance 0.02 dx
    for x in (0.2, 0.213, 0.005, L - 0.005):
        assert water_level([x, 0.0], arrays, DX) == pytest.approx(H, abs=0.02 * DX), x
    dry = {k: v[arrays["kind"] == 1] for k, v in arrays.items()}
    assert water_level([0.2, 0.0], dry, DX) == 0.0  # a dry line reads its bottom


def test_volume_and_mean_velocity_in_a_box():
    arrays = _tank_2d(velocity=(0.3, -0.1))
    # box edges between lattice rows: exactly the particles inside, each of volume dx^2
    assert water_volume_in_box([0.1, 0.0], [0.3, 0.1], arrays) == pytest.approx(0.2 * 0.1, rel=1e-12)
    assert water_volume_in_box([0.0, -0.1], [L, L], arrays) == pytest.approx(L * H, rel=1e-12)
    # porosity: a particle holds eps of its bulk volume as water
    wet = dict(arrays, porosity=np.full(len(arrays["kind"]), 0.4))
    assert water_volume_in_box([0.0, 0.0], [L, L], wet) == pytest.approx(0.4 * L * H, rel=1e-12)
    np.testing.assert_allclose(mean_velocity_in_box([0.1, 0.0], [0.3, 0.1], arrays), [0.3, -0.1], rtol=1e-12)
    assert np.isnan(mean_velocity_in_box([0.1, H + DX], [0.3, L], arrays)).all()
    inactive = dict(arrays, active=np.zeros(len(arrays["kind"]), bool))
    assert water_volume_in_box([0.0, 0.0], [L, L], inactive) == 0.0


def _config(probes):
    return load_config(data={
        "dim": 2, "dx": DX, "end_time": 1.0, "dt": 0.01, "output": {"every": 0.1},
        "tank": {"size": [L, L]}, "water": [{"min": [0, 0], "max": [L, H]}], "probes": probes})


PROBES = [
    {"name": "p_mid", "type": "pressure", "point": [0.2, 0.1]},
    {"name": "level", "type": "water_level", "point": [0.2, 0.0], "every": 0.25},
    {"name": "vol", "type": "water_volume", "box": {"min": [0.0, 0.0], "max": [0.4, 0.15]}, "every": 0.05},
    {"name": "vel", "type": "velocity", "box": {"min": [0.1, 0.0], "max": [0.3, 0.2]}},
]


def test_each_probe_is_sampled_at_zero_then_at_the_first_step_at_or_after_each_multiple():
    cfg = _config(PROBES)
    ps = ProbeSet(cfg.probes, cfg.dim, cfg.dx, cfg.output.every)
    arrays = _tank_2d()
    taken = {p["name"]: [] for p in PROBES}
    for t in np.round(np.arange(0.0, 0.6, 0.03), 10):  # steps of 0.03 s: never exactly on 0.1 or 0.25
        for name in ps.sample(t, arrays, ps.due(t)):
            taken[name].append(t)
    np.testing.assert_allclose(taken["p_mid"], [0.0, 0.12, 0.21, 0.3, 0.42, 0.51])
    np.testing.assert_allclose(taken["level"], [0.0, 0.27, 0.51])
    # every 0.05 s with 0.03 s steps: multiples skipped over are not sampled twice
    np.testing.assert_allclose(taken["vol"], [0.0, 0.06, 0.12, 0.15, 0.21, 0.27, 0.3, 0.36, 0.42, 0.45, 0.51, 0.57])
    assert ps.columns() == ["p_mid", "level", "vol", "vel_x", "vel_y"]


def test_csv_equals_run_file_and_loads_with_numpy(tmp_path):
    cfg = _config(PROBES)
    arrays = _tank_2d(velocity=(0.05, 0.0))
    out = tmp_path / "run.h5"
    writer = RunWriter(out, mode="isph", dim=2, dx=DX, arch="cpu", config_yaml="", kind=arrays["kind"],
                       ids=np.arange(len(arrays["kind"])), code_version="t")
    rec = ProbeRecorder(ProbeSet(cfg.probes, cfg.dim, cfg.dx, cfg.output.every), writer, out.with_suffix(".probes.csv"))
    rng = np.random.default_rng(3)
    for step in range(13):
        t = 0.05 * step
        a = dict(arrays, pressure=arrays["pressure"] * (1 + 0.01 * rng.standard_normal()),
                 position=arrays["position"] + 1e-4 * rng.standard_normal(arrays["position"].shape))
        rec.record(t, a, rec.due(t))
        if step % 4 == 3:
            rec.flush()
    rec.close()
    writer.close()

    table = np.genfromtxt(tmp_path / "run.probes.csv", delimiter=",", names=True)
    assert table.dtype.names == ("time", "p_mid", "level", "vol", "vel_x", "vel_y")
    with RunFile(out) as rf:
        probes = rf.probes()
        units = rf.probe_units()
        assert units == {"p_mid": "Pa", "level": "m", "vol": "m^2", "vel": "m/s"}
        assert rf.h5["probes/level"].attrs["type"] == "water_level"
    for name, cols in (("p_mid", ["p_mid"]), ("level", ["level"]), ("vol", ["vol"]), ("vel", ["vel_x", "vel_y"])):
        t, v = probes[name]
        rows = ~np.isnan(table[cols[0]])
        np.testing.assert_array_equal(table["time"][rows], t)  # exact: shortest round-trip repr
        got = np.stack([table[c][rows] for c in cols], axis=1)
        np.testing.assert_array_equal(got, v.reshape(len(t), -1))
    assert len(probes["level"][0]) == 3 and len(probes["vol"][0]) == 13 and len(probes["p_mid"][0]) == 7


def test_surge_front_is_the_edge_of_the_water_body():
    """A column [0, a] x [0, 2a] on a floor: the front on the line of the first particle layer reads the
    face itself (the leading particle centre lies dx / 2 behind it); a lone droplet ahead does not count; a
    film one particle thick on the floor does, up to the edge of its last particle."""
    a = 0.2
    water = _lattice([0, 0], [a, 2 * a])
    wall = np.concatenate([_lattice([-3 * DX, -3 * DX], [1.0, 0]), _lattice([-3 * DX, 0], [0, 2 * a])])

    def arrays(extra):
        pos = np.concatenate([water, extra, wall])
        kind = np.r_[np.zeros(len(water) + len(extra)), np.ones(len(wall))].astype(np.int8)
        return {"position": pos, "kind": kind, "active": np.ones(len(pos), bool),
                "volume": np.full(len(pos), DX * DX)}

    line = [0.0, DX / 2]
    # measured 0.0015 dx off at the floor and 0.003 dx higher up: the kernel sum of a half-lattice is 0.5
    # at its edge to a few 1e-3; bound 0.02 dx
    assert surge_front(line, arrays(np.zeros((0, 2))), DX) == pytest.approx(a, abs=0.02 * DX)
    assert surge_front([0.0, a], arrays(np.zeros((0, 2))), DX) == pytest.approx(a, abs=0.02 * DX)
    droplet = np.array([[a + 4.5 * DX, DX / 2]])
    assert surge_front(line, arrays(droplet), DX) == pytest.approx(a, abs=0.02 * DX)
    # a 10-particle film reads 9.67 dx: its last particle alone holds phi = 0.5 about 0.17 dx past its centre
    film = np.stack([a + DX / 2 + DX * np.arange(10), np.full(10, DX / 2)], axis=1)
    assert 9.5 * DX < surge_front(line, arrays(film), DX) - a < 10.0 * DX


def _sand_bed(top=0.2, water_top=None):
    """A soil lattice [0, L] x [0, top] over a floor, with water to `water_top` over it (pore water on the
    same lattice, as mode wcsph_biot fills a bed), and plastic strain growing with x."""
    soil = _lattice([0, 0], [L, top])
    water = _lattice([0, 0], [L, water_top]) if water_top else np.zeros((0, 2))
    floor = _lattice([-3 * DX, -3 * DX], [L + 3 * DX, 0])
    pos = np.concatenate([soil, water, floor])
    kind = np.r_[np.full(len(soil), 2), np.zeros(len(water)), np.ones(len(floor))].astype(np.int8)
    strain = np.where(kind == 2, pos[:, 0], 0.0)
    return {"position": pos, "velocity": np.zeros_like(pos), "pressure": np.zeros(len(pos)), "kind": kind,
            "active": np.ones(len(pos), bool), "volume": np.full(len(pos), DX * DX), "plastic_strain": strain}


def test_soil_level_reads_the_bed_surface_and_its_uplift():
    from taichi_sph.probes import soil_level_in_box

    arrays = _sand_bed()
    # a flat lattice surface: the top row at 0.19 plus dx / 2 is the block's face, exactly
    assert soil_level_in_box([0.1, 0.0], [0.3, 1.0], arrays, DX) == pytest.approx(0.2, abs=1e-12)
    # lift the top row of half the box's columns by 1 mm: the mean rises by half of it
    pos = arrays["position"]
    lifted = (arrays["kind"] == 2) & (pos[:, 1] > 0.18) & (pos[:, 0] > 0.1) & (pos[:, 0] < 0.2)
    pos[lifted, 1] += 1e-3
    assert soil_level_in_box([0.1, 0.0], [0.3, 1.0], arrays, DX) == pytest.approx(0.2 + 0.5e-3, abs=1e-12)
    # columns with no soil in the box read its bottom
    assert soil_level_in_box([0.1, 0.25], [0.3, 1.0], arrays, DX) == pytest.approx(0.25, abs=1e-12)


def test_plastic_strain_and_water_depth_probes():
    from taichi_sph.probes import max_plastic_strain_in_box, water_depth

    arrays = _sand_bed(top=0.2, water_top=0.26)
    # the largest strain of the soil in the box: the particle nearest its right face (strain = x here)
    assert max_plastic_strain_in_box([0.1, 0.0], [0.2, 0.3], arrays) == pytest.approx(0.19, abs=1e-12)
    assert max_plastic_strain_in_box([0.1, 0.25], [0.2, 0.3], arrays) == 0.0  # no soil there
    # 6 cm of water over the bed: the water level (the kernel surface, within 0.05 dx of the block's face
    # as test_water_level_* measures) less the soil top
    assert water_depth([0.21, 0.0], arrays, DX) == pytest.approx(0.06, abs=0.05 * DX)
    # water only in the pores, its table 4 cm under the surface: nothing stands on the ground
    assert water_depth([0.21, 0.0], _sand_bed(top=0.2, water_top=0.16), DX) == 0.0


def test_water_front_reads_the_farthest_pore_water_in_its_box():
    """water_front: the largest x of the water inside the box (a wetting front's foot), whatever soil or
    wall stands farther; the box's low x when it holds no water. Exact: it picks a particle's place."""
    from taichi_sph.probes import water_front_in_box

    arrays = _sand_bed(top=0.2, water_top=0.1)  # soil on [0, L] x [0, 0.2], pore water below 0.1
    pos, kind, active = arrays["position"], arrays["kind"], arrays["active"]
    front = pos[kind == 0, 0].max()  # L - dx / 2 on the lattice
    assert water_front_in_box([0.0, 0.0], [1.0, 1.5 * DX], arrays) == front
    # a wetting front half way: take away the pore water beyond 0.2 m; the soil beyond stays
    active[(kind == 0) & (pos[:, 0] > 0.2)] = False
    assert water_front_in_box([0.0, 0.0], [1.0, 1.5 * DX], arrays) == pytest.approx(0.19)
    # one particle run ahead along the floor counts (the probe follows single particles)
    k = int(np.flatnonzero((kind == 0) & (pos[:, 0] > 0.3) & (pos[:, 1] < DX))[0])
    active[k] = True
    assert water_front_in_box([0.0, 0.0], [1.0, 1.5 * DX], arrays) == pos[k, 0]
    # a box above the floor row leaves it out; a box without water reads its low x
    assert water_front_in_box([0.0, 0.04], [1.0, 0.06], arrays) == pytest.approx(0.19)
    assert water_front_in_box([0.25, 0.15], [1.0, 0.3], arrays) == 0.25
