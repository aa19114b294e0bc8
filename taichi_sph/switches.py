"""The physics switches of a run: one frozen record, built once from the validated config and its scene,
that both the solvers (their `ti.static` flags, set in `__init__` from it) and `taichi-sph info --config`
(features.py) read, so what a run compiles and what `info` reports cannot differ.

Each switch belongs to one mode or to both (`MODES` of its field); the other mode's switches are None.
Every switch but `viscosity` is a compile-time flag: physics it turns off is compiled out of the
solver's kernels. `viscosity` (a viscosity above zero) is reported the same way, though the viscous
terms are always compiled.

This module imports numpy only (never taichi): `info --config` builds the scene and these switches
without starting a solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from .kinds import AIR, SOIL, WATER

ISPH, WCSPH = "isph", "wcsph_biot"
BOTH = (ISPH, WCSPH)


def _switch(modes: tuple, doc: str):
    return field(default=None, metadata={"modes": modes, "doc": doc})


@dataclass(frozen=True)
class Switches:
    """What a run compiles (True: the physics is in the kernels). Build with `Switches.build`."""

    mode: str
    # ---- both modes
    no_slip: bool | None = _switch(BOTH, "no-slip walls (tank.boundary: no_slip); else slip")
    periodic: bool | None = _switch(BOTH, "some axis is periodic (tank.periodic): wrapped positions, "
                                          "minimum-image pair differences")
    moving_walls: bool | None = _switch(BOTH, "some obstacle has a prescribed motion")
    viscosity: bool | None = _switch(BOTH, "a viscosity above zero (reported; the viscous terms are always "
                                           "compiled)")
    # ---- mode isph
    dry_walls: bool | None = _switch((ISPH,), "gravity is on: a side-wall particle above the water counts "
                                              "as air (left out of every sum)")
    porous: bool | None = _switch((ISPH,), "porous ground: the scene has soil markers (soil.regions)")
    turbulence: bool | None = _switch((ISPH,), "Smagorinsky eddy viscosity (fluid.turbulence: smagorinsky)")
    gradient: str | None = _switch((ISPH,), "pressure gradient form (isph.gradient)")
    pore_advection: bool | None = _switch((ISPH,), "particles advected at the pore velocity "
                                                   "(isph.advection: pore); else the Darcy velocity")
    ground_cone: bool | None = _switch((ISPH,), "free surface in and next to the ground confirmed by an empty "
                                                "cone (porous ground and isph.ground_surface_cone > 0)")
    ground_tension: bool | None = _switch((ISPH,), "with the cone: free water next to the ground, and pore water in "
                                                   "drained ground, that the pressure equation holds in tension "
                                                   "becomes free surface (isph.ground_surface_tension, "
                                                   "isph.ground_tension_fill)")
    tension_memory: bool | None = _switch((ISPH,), "with the tension rule: a candidate in tension that was free "
                                                   "surface at the end of the last step is freed again "
                                                   "(isph.ground_tension_memory)")
    pore_density: bool | None = _switch((ISPH,), "porous ground: eq 31's stabilisation reads pore water over the "
                                                 "pore lattice's support (isph.ground_density_support: pore or "
                                                 "interior)")
    pore_interior: bool | None = _switch((ISPH,), "with the pore support: only where it lies in uniform ground, r_e "
                                                  "elsewhere (isph.ground_density_support: interior)")
    ground_drained: bool | None = _switch((ISPH,), "with the cone: drained pore water is a candidate of the cone "
                                                   "test (isph.ground_drained_candidate)")
    air_entry: bool | None = _switch((ISPH,), "pore water's suction clamped at the ground's air-entry value "
                                              "(porous ground and isph.air_entry_suction)")
    ground_correction: bool | None = _switch((ISPH,), "the kernel-gradient correction also inside saturated porous ground of weak drag "
                                                      "(gradient corrected and isph.ground_gradient_correction)")
    shifting: bool | None = _switch((ISPH,), "particle shifting (isph.shifting > 0)")
    collisions: bool | None = _switch((ISPH,), "collision handling (isph.collision_distance > 0)")
    free_surface: bool | None = _switch((ISPH,), "free-surface detection, eq 34 (n_surf > 0)")
    ppe_ell: bool | None = _switch((ISPH,), "ELL matrix for the PPE (isph.ppe.type: ell_pcg, Jacobi-PCG, "
                                            "or mg_pcg, multigrid-PCG); else the sparse builder")
    # ---- mode wcsph_biot
    air: bool | None = _switch((WCSPH,), "the scene has air particles")
    cohesion: bool | None = _switch((WCSPH,), "eq 54 cohesion of water or air (a cohesion above zero and "
                                              "particles of that material)")
    artificial_viscosity: bool | None = _switch((WCSPH,), "eq 36 (alpha or beta above zero)")
    xsph: bool | None = _switch((WCSPH,), "eq 53 XSPH correction (wcsph.xsph > 0)")
    density_diffusion: bool | None = _switch((WCSPH,), "the water's density diffusion (delta-SPH; "
                                                       "wcsph.density_diffusion above zero)")
    density_diffusion_gradient: bool | None = _switch((WCSPH,), "the density diffusion's gradient correction "
                                                                "(wcsph.density_diffusion_form: gradient)")
    variable_h: bool | None = _switch((WCSPH,), "eq 52 variable smoothing length")
    normalised_density: bool | None = _switch((WCSPH,), "eq 27 density normalisation every normalise_every "
                                                        "steps (wcsph.density: normalised)")
    soil: bool | None = _switch((WCSPH,), "the scene has soil particles (eq 35, 37-45)")
    soil_water: bool | None = _switch((WCSPH,), "soil and water together: pore pressure and Biot drag "
                                                "(eq 46-47)")
    soil_air: bool | None = _switch((WCSPH,), "soil and air together: Biot drag of eq 46-47 between them "
                                              "(the soil's conductivity for air wcsph.soil.air_permeability)")
    soil_fixed: bool | None = _switch((WCSPH,), "the whole skeleton is rigid (wcsph.soil.fixed)")
    pore_volume: bool | None = _switch((WCSPH,), "water particles in the soil fill its pores only: partial "
                                                 "density, pore velocity (wcsph.soil.pore_water)")
    soil_blocks_fixed: bool | None = _switch((WCSPH,), "some soil particles are held by "
                                                       "soil_blocks[k].fixed")
    soil_dilatancy: bool | None = _switch((WCSPH,), "plastic flow changes the soil's volume "
                                                    "(wcsph.soil.dilatancy_angle > 0)")

    @classmethod
    def build(cls, cfg, scene) -> "Switches":
        """The switches of a validated config and the scene built from it (scene.build_scene)."""
        kind = np.asarray(scene.kind)
        n_water, n_air, n_soil = (int(np.count_nonzero(kind == k)) for k in (WATER, AIR, SOIL))
        common = dict(no_slip=cfg.tank.boundary == "no_slip",
                      periodic=any(v > 0.0 for v in scene.periods()),
                      moving_walls=bool(scene.motions))
        if cfg.mode == ISPH:
            g_abs = float(np.linalg.norm(np.asarray(cfg.gravity_vector(), dtype=float)))
            i = cfg.isph
            return cls(mode=ISPH, **common, viscosity=cfg.fluid.viscosity > 0.0, dry_walls=g_abs > 0.0,
                       porous=bool(scene.markers),
                       ground_cone=bool(scene.markers) and i.ground_surface_cone > 0.0,
                       ground_tension=bool(scene.markers) and i.ground_surface_cone > 0.0
                       and i.ground_surface_tension,
                       tension_memory=bool(scene.markers) and i.ground_surface_cone > 0.0
                       and i.ground_surface_tension and i.ground_tension_memory,
                       pore_density=bool(scene.markers) and i.ground_density_support in ("pore", "interior"),
                       pore_interior=bool(scene.markers) and i.ground_density_support == "interior",
                       ground_drained=bool(scene.markers) and i.ground_surface_cone > 0.0
                       and i.ground_drained_candidate,
                       air_entry=bool(scene.markers) and i.air_entry_suction is not None,
                       ground_correction=bool(scene.markers) and i.gradient == "corrected"
                       and i.ground_gradient_correction,
                       turbulence=cfg.fluid.turbulence == "smagorinsky",
                       gradient=i.gradient,
                       pore_advection=i.advection == "pore",
                       shifting=i.shifting > 0,
                       collisions=i.collision_distance > 0,
                       free_surface=cfg.n_surf() > 0,
                       ppe_ell=i.ppe.type in ("ell_pcg", "mg_pcg"))
        w = cfg.wcsph
        air = n_air > 0
        sp = w.soil
        return cls(mode=WCSPH, **common,
                   # (the air's Morris pair coefficient with water mixes in the water's viscosity)
                   viscosity=(cfg.fluid.viscosity > 0.0 and (n_water > 0 or air))
                   or (w.air.viscosity > 0.0 and air),
                   air=air,
                   cohesion=(w.water.cohesion > 0.0 and n_water > 0) or (w.air.cohesion > 0.0 and air),
                   artificial_viscosity=w.artificial_viscosity.alpha > 0.0 or w.artificial_viscosity.beta > 0.0,
                   xsph=w.xsph > 0.0,
                   density_diffusion=cfg.density_diffusion() > 0.0 and n_water > 0,
                   density_diffusion_gradient=(cfg.density_diffusion() > 0.0 and n_water > 0
                                               and w.density_diffusion_form == "gradient"),
                   variable_h=bool(w.variable_h),
                   normalised_density=w.density == "normalised",
                   soil=n_soil > 0,
                   soil_water=n_soil > 0 and n_water > 0,
                   soil_air=n_soil > 0 and air and cfg.air_conductivity() is not None,
                   soil_fixed=bool(sp.fixed),
                   pore_volume=n_soil > 0 and n_water > 0 and sp.pore_water == "pore_volume",
                   soil_blocks_fixed=len(held_soil_ids(cfg, scene)) > 0,
                   soil_dilatancy=n_soil > 0 and sp.dilatancy_angle > 0.0)

    def report(self) -> dict:
        """{switch: value} of this mode's switches (JSON-serialisable)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name != "mode" and self.mode in f.metadata["modes"]}


def held_soil_ids(cfg, scene) -> np.ndarray:
    """Ids of the soil particles held rigid on their own (`soil_blocks[k].fixed`, a permeable base): none
    when the whole skeleton is fixed (wcsph.soil.fixed) or no block is."""
    kind = np.asarray(scene.kind)
    if cfg.mode != WCSPH or cfg.wcsph.soil.fixed or not any(b.fixed for b in cfg.soil_blocks):
        return np.zeros(0, np.int64)
    soil_idx = np.nonzero(kind == SOIL)[0]
    if not len(soil_idx):
        return np.zeros(0, np.int64)
    from .scene import soil_block_index

    blk = soil_block_index(cfg, scene.position[soil_idx])
    held = np.array([b.fixed for b in cfg.soil_blocks])[np.maximum(blk, 0)] & (blk >= 0)
    return np.asarray(scene.ids)[soil_idx[held]]
