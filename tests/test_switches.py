"""What `taichi-sph info --config` reports (features.py) is what the solver compiles: for every config in
configs/, and each of its variants that changes a switch, the switches `features` reports equal the flags
the solver's kernels read (`ti.static(self.<flag>)`), read back from a solver built from that config.
(Building a solver costs 0.5-4 s; the variants that leave every switch as the config's default have
that default's solver.)"""

from pathlib import Path

import pytest

from taichi_sph.config import load_config
from taichi_sph.errors import InputError
from taichi_sph.features import features

ROOT = Path(__file__).resolve().parents[1]

#: the flags each solver's kernels read, as the switch names of taichi_sph/switches.py; a switch added
#: there must be added here (test_every_switch_is_checked)
GRADIENT = {0: "corrected", 1: "difference", 2: "symmetric"}  # isph/solver.py GRAD_*
ISPH_FLAGS = {
    "no_slip": lambda s: s.no_slip,
    "periodic": lambda s: s.periodic,
    "moving_walls": lambda s: s.motion.any,
    "viscosity": lambda s: s.nu > 0.0,
    "dry_walls": lambda s: s.dry_walls,
    "porous": lambda s: s.porous,
    "turbulence": lambda s: s.turbulence,
    "gradient": lambda s: GRADIENT[s.grad_mode],
    "pore_advection": lambda s: s.pore_advection,
    "shifting": lambda s: s.shifting,
    "ground_cone": lambda s: s.ground_cone,
    "ground_tension": lambda s: s.ground_tension,
    "tension_memory": lambda s: s.tension_memory,
    "pore_density": lambda s: s.pore_density,
    "pore_interior": lambda s: s.pore_interior,
    "ground_drained": lambda s: s.drained_candidate,
    "air_entry": lambda s: s.suction_floor > 0.0,
    "ground_correction": lambda s: s.ground_correction,
    "collisions": lambda s: s.collision,
    "free_surface": lambda s: s.n_surf > 0,
    "ppe_ell": lambda s: s.ppe_ell,
}
WCSPH_FLAGS = {
    "no_slip": lambda s: s.no_slip,
    "periodic": lambda s: s.periodic,
    "moving_walls": lambda s: s.moving,
    "viscosity": lambda s: s.nu_max > 0.0,
    "air": lambda s: s.has_air,
    "cohesion": lambda s: s.cohesion_on,
    "artificial_viscosity": lambda s: s.av_on,
    "xsph": lambda s: s.xsph_on,
    "density_diffusion": lambda s: s.dd_on,
    "density_diffusion_gradient": lambda s: s.dd_grad,
    "variable_h": lambda s: s.variable_h,
    "normalised_density": lambda s: s.normalised,
    "soil": lambda s: s.has_soil,
    "soil_water": lambda s: s.coupled,
    "soil_air": lambda s: s.soil_air,
    "soil_fixed": lambda s: s.soil.soil_fixed,
    "pore_volume": lambda s: s.partial,
    "soil_blocks_fixed": lambda s: s.soil.block_fixed,
    "soil_dilatancy": lambda s: s.soil.dilatant,
}
FLAGS = {"isph": ISPH_FLAGS, "wcsph_biot": WCSPH_FLAGS}


def _cases():
    """(id, config path, variant) for every config of configs/ (sweep files aside) and its variants."""
    import yaml

    out = []
    for path in sorted((ROOT / "configs").glob("*.yaml")):
        data = yaml.safe_load(path.read_text())
        if "mode" not in data:  # a sweep file
            continue
        out.append(pytest.param(path, None, id=path.stem))
        out += [pytest.param(path, v, id=f"{path.stem}-{v}") for v in data.get("variants") or {}]
    return out


def _load(path, variant):
    """The config; a second stage whose first stage's run file is missing starts from K0 instead (the
    switches do not depend on where the soil's stress starts)."""
    try:
        return load_config(path, [], variant)
    except InputError as exc:
        if "wcsph.soil.start_from" not in str(exc):
            raise
        return load_config(path, ["wcsph.soil.start_from=null"], variant)


@pytest.mark.parametrize("path, variant", _cases())
def test_reported_switches_are_the_compiled_ones(ti_cpu, path, variant):
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    cfg = _load(path, variant)
    reported = features(cfg)  # builds its own scene, as `info --config` does
    if variant is not None and reported["switches"] == features(_load(path, None))["switches"]:
        return  # compiled as the config's default, checked there
    solver = make_solver(cfg, build_scene(cfg))
    compiled = {name: bool(get(solver)) if name != "gradient" else get(solver)
                for name, get in FLAGS[cfg.mode].items()}
    assert reported["switches"] == compiled
    # the neighbour grid and the wall motion wrap on their own flags, from the same periods
    assert solver.grid._any_periodic == solver.motion.periodic == compiled["periodic"]
    assert solver.motion.any == compiled["moving_walls"]
    physics = reported["physics"]
    assert physics["porous_ground"] == (cfg.mode == "isph" and compiled["porous"])
    assert physics["turbulence"] == (cfg.mode == "isph" and compiled["turbulence"])
    assert physics["viscosity"] == compiled["viscosity"]


def test_every_switch_is_checked():
    from dataclasses import fields

    from taichi_sph.switches import Switches

    for mode, flags in FLAGS.items():
        names = {f.name for f in fields(Switches) if mode in f.metadata.get("modes", ())}
        assert names == set(flags), mode


def test_free_fall_reports_its_porous_ground(run_cli):
    """configs/freefall.yaml has soil markers in a porous layer (soil.regions); `info` said it had none."""
    import json

    proc = run_cli("info", "--config", "configs/freefall.yaml", "--json", timeout=120)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["physics"]["porous_ground"] is True and data["switches"]["porous"] is True
    assert data["physics"]["turbulence"] is True  # fluid.turbulence: smagorinsky
    assert "[Taichi]" not in proc.stdout + proc.stderr
    proc = run_cli("info", "--config", "configs/hydrostatic.yaml", "--json", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["physics"]["porous_ground"] is False
