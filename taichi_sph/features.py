"""Which physics and options a config enables (what `taichi-sph info --config` prints)."""

from __future__ import annotations


def features(cfg) -> dict:
    """A JSON-serialisable description of the physics a validated config compiles and runs."""
    return {
        "mode": cfg.mode,
        "dim": cfg.dim,
        "dx": cfg.dx,
        "dt": cfg.dt,
        "end_time": cfg.end_time,
        "physics": {
            "viscosity": cfg.fluid.viscosity > 0,
            "turbulence": cfg.fluid.turbulence,
            "porous_ground": False,
            "walls": cfg.tank.boundary,
            "obstacles": len(cfg.obstacles),
            "gravity": cfg.gravity_vector(),
        },
        "isph": {
            "alpha": cfg.isph.alpha,
            "n_surf": cfg.n_surf(),
            "free_surface_pressure": cfg.isph.free_surface_pressure,
            "gradient": cfg.isph.gradient,
            "ppe_solver": cfg.isph.ppe.type,
            "ppe_tolerance": cfg.isph.ppe.tolerance,
            "ppe_max_iterations": cfg.isph.ppe.max_iterations,
        },
        "output": {"path": cfg.output.path, "every": cfg.output.every},
        "probes": {p.name: {"type": p.type, "every": p.every or cfg.output.every} for p in cfg.probes},
        "images": (None if cfg.output.images is None else
                   {"every": cfg.output.images.every, "field": cfg.output.images.field}),
        **_wcsph_features(cfg),
    }


def _wcsph_features(cfg) -> dict:
    """The physics switches of mode wcsph_biot (each a compile-time flag of its solver)."""
    if cfg.mode != "wcsph_biot":
        return {}
    w = cfg.wcsph
    return {"wcsph": {
        "materials": ["water"] + (["air"] if cfg.air else []),
        "density": w.density,
        "normalise_every": w.normalise_every,
        "water_sound_speed": cfg.sound_speed(),
        "artificial_viscosity": w.artificial_viscosity.alpha > 0 or w.artificial_viscosity.beta > 0,
        "xsph": w.xsph,
        "variable_h": w.variable_h,
        "cohesion": {"water": w.water.cohesion, "air": w.air.cohesion},
        "walls": cfg.tank.boundary,
        "beta_max": w.beta_max,
        "release_velocity": w.release_velocity,
    }}
