"""Which physics and options a config enables (what `taichi-sph info --config` prints). The physics
switches come from taichi_sph/switches.py, the record the solvers set their compile-time flags from."""

from __future__ import annotations

from .backend import no_taichi_banner, resolved_precision
from .switches import Switches


def build_scene_quietly(cfg):
    """The config's scene (scene.build_scene) without Taichi's banner on stdout: scene.py imports
    Taichi through its kernels, and `info --json` prints nothing but JSON."""
    with no_taichi_banner():
        from .scene import build_scene
    return build_scene(cfg)


def features(cfg, scene=None) -> dict:
    """A JSON-serialisable description of the physics a validated config compiles and runs; `scene`
    (scene.build_scene of cfg) is built when not given. `switches` holds every compile-time physics
    switch of the config's mode (Switches.report)."""
    sw = Switches.build(cfg, scene if scene is not None else build_scene_quietly(cfg))
    return {
        "mode": cfg.mode,
        "dim": cfg.dim,
        "dx": cfg.dx,
        "dt": cfg.dt,
        "end_time": cfg.end_time,
        "physics": {
            "viscosity": sw.viscosity,
            "turbulence": bool(sw.turbulence),
            "porous_ground": bool(sw.porous),
            "walls": cfg.tank.boundary,
            "obstacles": len(cfg.obstacles),
            "gravity": cfg.gravity_vector(),
        },
        # what `precision` resolves to on the CPU and on a GPU (`arch: auto` takes a GPU where there is one)
        "precision": {"setting": cfg.precision, "arch": cfg.arch,
                      "cpu": resolved_precision(cfg.precision, False, cfg.mode),
                      "gpu": resolved_precision(cfg.precision, True, cfg.mode)},
        "output": {"path": cfg.output.path, "every": cfg.output.every},
        "probes": {p.name: {"type": p.type, "every": p.every or cfg.output.every} for p in cfg.probes},
        "images": (None if cfg.output.images is None else
                   {"every": cfg.output.images.every, "field": cfg.output.images.field}),
        "switches": sw.report(),
        **_isph_features(cfg),
        **_wcsph_features(cfg, sw),
    }


def _isph_features(cfg) -> dict:
    """The options of mode isph (its switches are under `switches`)."""
    if cfg.mode != "isph":
        return {}
    return {"isph": {
        "alpha": cfg.isph.alpha,
        "n_surf": cfg.n_surf(),
        "free_surface_pressure": cfg.isph.free_surface_pressure,
        "gradient": cfg.isph.gradient,
        "ppe_solver": cfg.isph.ppe.type,
        "ppe_tolerance": cfg.isph.ppe.tolerance,
        "ppe_max_iterations": cfg.isph.ppe.max_iterations,
    }}


def _wcsph_features(cfg, sw: Switches) -> dict:
    """The options of mode wcsph_biot (its switches are under `switches`)."""
    if cfg.mode != "wcsph_biot":
        return {}
    w = cfg.wcsph
    return {"wcsph": {
        "materials": ["water"] + (["air"] if sw.air else []) + (["soil"] if sw.soil else []),
        "density": w.density,
        "normalise_every": w.normalise_every,
        "water_sound_speed": cfg.sound_speed(),
        "artificial_viscosity": sw.artificial_viscosity,
        "artificial_viscosity_speed": cfg.viscosity_speed(),
        "density_diffusion": cfg.density_diffusion(),
        "density_diffusion_form": w.density_diffusion_form,
        "xsph": w.xsph,
        "variable_h": w.variable_h,
        "cohesion": {"water": w.water.cohesion, "air": w.air.cohesion},
        "walls": cfg.tank.boundary,
        "beta_max": w.beta_max,
        "release_velocity": w.release_velocity,
        # the soil's conductivity for air (m/s) where air drags on soil (switch soil_air)
        "air_conductivity": cfg.air_conductivity() if sw.soil_air else None,
    }}
