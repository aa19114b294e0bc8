"""Config schema: every key a case accepts, its default, its unit and its bounds.

All quantities are SI (m, s, kg, Pa). Vertical is the last axis (y in 2D, z in 3D) and gravity
points down it unless `gravity` says otherwise. The tank interior spans [0, size] on every axis;
walls are built outside it. Validation runs before any Taichi kernel is compiled; cross-field rules
(list lengths equal to `dim`, blocks inside the tank, options valid for the mode) live in
`check`. Keys are documented in docs/config.md.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..errors import InputError

PosFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]
PosInt = Annotated[int, Field(gt=0)]


class Strict(BaseModel):
    """Base: unknown keys are errors; no coercion of strings or booleans to numbers; no inf or nan."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, validate_default=True)


class Box(Strict):
    """Axis-aligned box [min, max] (m)."""

    min: list[float]
    max: list[float]

    @model_validator(mode="after")
    def _ordered(self):
        if len(self.min) != len(self.max):
            raise ValueError("min and max must have the same length")
        for a, b in zip(self.min, self.max):
            if not b > a:
                raise ValueError(f"max must exceed min on every axis (min={self.min}, max={self.max})")
        return self


class WaterBlock(Box):
    """A block of water particles (m)."""

    #: fill the block at the density of water in ground of this porosity: lattice spacing
    #: dx / porosity^(1/dim), so each particle keeps the mass rho_w dx^dim (seed 000 eq 33)
    porosity: Annotated[float, Field(gt=0, le=1)] = 1.0
    #: random displacement of each particle, uniform in [-jitter, jitter] x dx along each axis (stability
    #: tests; a fixed seed, so a run repeats); at most 0.5
    jitter: Annotated[float, Field(ge=0, le=0.5)] = 0.0
    #: initial velocity of the block's particles: rest, or the 2D Taylor-Green vortex
    #: u = U sin(kx x) cos(ky y), v = -U (kx / ky) cos(kx x) sin(ky y), k = 2 pi / L with L the tank
    #: size along that axis (needs dim 2 and both axes in `tank.periodic`)
    initial_velocity: Literal["rest", "taylor_green"] = "rest"
    #: U of `initial_velocity` (m/s)
    velocity_scale: NonNegFloat = 1.0
    #: mode wcsph_biot: start the block's particles at the hydrostatic pressure of this free-surface
    #: height, rho_w |g| (start_head - height) (m), instead of the weight of the fluid above them (a
    #: plenum under a baffle or a permeable base, fed from a reservoir at that level); default none
    start_head: float | None = None
    #: mode wcsph_biot: keep only the block's lattice points inside soil blocks, so that the block
    #: fills the pores of the ground up to its top (a levee saturated up to a phreatic level) and
    #: leaves the open ground above and beside the soil dry; needs `soil_blocks`
    inside_soil: bool = False


class SoilRegion(Strict):
    """A region of porous ground, filled with fixed soil markers (seed 000 section 4)."""

    #: box: an axis-aligned block [min, max]; mound: a trapezoid in the plane of the first and the
    #: vertical axis (toe at `bottom`, crest at `top`), across the whole tank along y in 3D
    shape: Literal["box", "mound"] = "box"
    #: box corners (m)
    min: Optional[list[float]] = None
    max: Optional[list[float]] = None
    #: mound: [x_left, x_right] of its base and of its crest (m)
    toe: Optional[list[float]] = None
    crest: Optional[list[float]] = None
    #: mound: heights of its base and of its crest (m)
    bottom: float = 0.0
    top: Optional[float] = None
    #: intrinsic porosity eps0 of the ground (1: no ground, the porous terms vanish)
    eps0: Annotated[float, Field(gt=0, le=1)]
    #: mean grain diameter D50 (m)
    d50: PosFloat

    @model_validator(mode="after")
    def _shape_keys(self):
        if self.shape == "box":
            if self.min is None or self.max is None:
                raise ValueError("a box region needs min and max")
            Box(min=self.min, max=self.max)
        else:
            if self.toe is None or self.crest is None or self.top is None:
                raise ValueError("a mound region needs toe, crest and top")
            for key, pair in (("toe", self.toe), ("crest", self.crest)):
                if len(pair) != 2 or not pair[1] > pair[0]:
                    raise ValueError(f"{key} must be [x_left, x_right] with x_right > x_left")
            if not self.top > self.bottom:
                raise ValueError("top must exceed bottom")
            if self.crest[0] < self.toe[0] or self.crest[1] > self.toe[1]:
                raise ValueError("the crest must lie within the toe")
        return self


class Soil(Strict):
    """Porous ground of mode isph: fixed soil markers give each water particle its porosity (eq 32)
    and the drag coefficients a, b of eq 9c-d."""

    #: the ground, as regions of markers; a later region replaces earlier ones where they overlap
    regions: list[SoilRegion] = []
    #: marker spacing (m); default dx
    marker_spacing: Optional[PosFloat] = None
    #: cells: markers at cell centres, the ground surface lies on the region's faces; nodes: markers on
    #: the region's faces and corners too (the seed's 21 x 21 x 21 markers for a 20 cm cube at 1 cm),
    #: which moves the surface half a spacing outwards
    lattice: Literal["cells", "nodes"] = "cells"
    #: linear (Ergun-type) drag constant alpha_c of eq 9c
    alpha_c: PosFloat = 1000.0
    #: quadratic drag constant beta_c of eq 9d
    beta_c: NonNegFloat = 1.1


class Output(Strict):
    #: run file (HDF5); `--out` overrides it
    path: str = "out/run.h5"
    #: simulated seconds between frames
    every: PosFloat = 0.02
    #: HDF5 compression of frame datasets
    compression: Literal["none", "gzip", "lzf"] = "none"
    #: pictures rendered while the run goes (PyVista, in a separate process); none by default
    images: Optional[Images] = None


#: particle fields a picture made during a run can be coloured by
ImageField = Literal["speed", "pressure", "density", "kind", "porosity", "velocity_x", "velocity_y", "velocity_z"]
#: a name usable as an HDF5 group and a CSV column in numpy and pandas
ProbeName = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", max_length=64)]


class Images(Strict):
    """Pictures while the run goes: at the first frame at or after every `every` seconds the run saves
    that frame's arrays and a separate renderer process draws <run>_images/<field>_<frame>.png (the
    simulation never waits for it and is never affected when rendering fails). Needs the `render` extra."""

    #: simulated seconds between pictures (at least output.every; pictures are made from frames)
    every: PosFloat
    #: particle field that colours the particles: speed, pressure, density, kind, porosity, velocity_x|y|z
    field: ImageField = "speed"
    #: camera preset (auto: front in 2D, iso in 3D)
    camera: Literal["auto", "iso", "front", "top", "side"] = "auto"
    #: wall particles: hidden, translucent or drawn
    walls: Literal["hide", "translucent", "show"] = "translucent"
    #: picture size in pixels [width, height]; rounded up to multiples of 16 so that videos encode cleanly
    size: list[PosInt] = [800, 608]
    #: colour range [lo, hi] in the field's unit; default: automatic for each picture
    range: Optional[list[float]] = None


class Probe(Strict):
    """A gauge sampled during the run, written to /probes/<name>/time|value of the run file and to
    <run>.probes.csv. See docs/output.md for how each type is computed."""

    #: unique name (letters, digits and '_', not starting with a digit): the HDF5 group and the CSV
    #: column (a velocity probe's columns are <name>_x, <name>_y[, <name>_z])
    name: ProbeName
    #: pressure: SPH (Shepard) pressure of the water at `point` (Pa); water_level: elevation of the
    #: water surface on the vertical line that rises from `point` (m); water_volume: water inside
    #: `box` (m^3, m^2 in 2D); velocity: mean velocity of the water inside `box` (m/s, dim components)
    type: Literal["pressure", "water_level", "water_volume", "velocity"]
    #: location (m), dim values, inside the tank (types pressure and water_level)
    point: Optional[list[float]] = None
    #: region (m), inside the tank (types water_volume and velocity)
    box: Optional[Box] = None
    #: simulated seconds between samples (default: output.every); sampled at the first step at or
    #: after each multiple, and at t = 0
    every: Optional[PosFloat] = None


class Fluid(Strict):
    #: water density rho_w (kg/m^3)
    density: PosFloat = 1000.0
    #: kinematic viscosity nu_w (m^2/s)
    viscosity: NonNegFloat = 1.0e-6
    #: sub-particle turbulence: Smagorinsky eddy viscosity nu_T = (Cs Delta)^2 |S| (seed 000 eq 3)
    turbulence: Literal["none", "smagorinsky"] = "none"
    smagorinsky_cs: PosFloat = 0.2


class Tank(Strict):
    #: interior extent (m) along each axis, from the origin
    size: list[PosFloat]
    #: layers of wall particles; default fills the kernel support (ceil(2.4) = 3)
    wall_layers: Optional[PosInt] = None
    #: velocity condition at walls
    boundary: Literal["no_slip", "slip"] = "no_slip"
    #: no lid: the top is open
    open_top: bool = True
    #: axes (0-based) whose two side walls are left out and replaced by periodic wrap: the tank size
    #: along such an axis is the period L (a whole number of dx, at least 3 neighbour-search cells:
    #: 7.2 dx in mode isph); particles leaving at L come back at 0, pairs see the nearest image
    periodic: list[int] = []


class ObstacleMotion(Strict):
    """Prescribed motion of an obstacle between `start` and `stop`: a rigid translation at constant
    `velocity` (a plate sliding along its face, a gate, a piston), or an oscillation of displacement
    `amplitude` sin(2 pi (t - start) / `period`) (a paddle). Give `velocity`, or `amplitude` and
    `period`. The obstacle's wall particles carry its velocity in the wall conditions of both modes
    (slip and no-slip are taken relative to it; across a periodic side the obstacle wraps). A face
    moving away from the water faster than the water can follow does not let go of it: see
    docs/moving_obstacles.md."""

    #: constant velocity (m/s), dim components
    velocity: Optional[list[float]] = None
    #: displacement amplitude of an oscillation (m), dim components
    amplitude: Optional[list[float]] = None
    #: period of the oscillation (s)
    period: Optional[PosFloat] = None
    #: time the motion starts (s)
    start: NonNegFloat = 0.0
    #: time the motion stops (s); default: never (it runs to end_time)
    stop: Optional[PosFloat] = None


class Obstacle(Box):
    """A solid block of wall particles inside the tank (m)."""

    #: prescribed motion; default: fixed
    motion: Optional[ObstacleMotion] = None


class PPESolver(Strict):
    #: sparse_cg: matrix assembled with ti.linalg.SparseMatrixBuilder, solved by SparseCG (Eigen CG
    #: on CPU); ell_pcg: matrix in ELL form in Taichi fields, Jacobi-preconditioned CG in Taichi
    #: kernels; mg_pcg: the same ELL matrix, CG preconditioned by a multigrid V-cycle on the
    #: neighbour grid's cells (iterations nearly independent of size: 1.7-4.7x faster steps in 2D
    #: from 10k to 200k particles, but 24 % slower on the 3D free fall of 8000; docs/performance.md)
    type: Literal["sparse_cg", "ell_pcg", "mg_pcg"] = "ell_pcg"
    #: relative residual |b - A p| / |b| to reach
    tolerance: PosFloat = 1.0e-8
    max_iterations: PosInt = 2000
    #: what to do when CG stops before the tolerance: stop the run, or record and go on
    on_failure: Literal["error", "warn"] = "error"
    #: ell_pcg and mg_pcg only: floats of the matrix and CG vectors; auto = f64 when the tolerance is below
    #: 1e-5 (f32 CG stalls near 1e-5 relative residual), else the run's precision
    precision: Literal["auto", "f32", "f64"] = "auto"
    #: ell_pcg and mg_pcg only: off-diagonal entries a row can hold (default: 1.5 x the kernel's lattice
    #: neighbour count, 30 in 2D and 84 in 3D, at most `neighbours.max`); a row that needs more
    #: widens the matrix during the run (with a warning)
    width: Optional[PosInt] = None


class ISPH(Strict):
    #: density-invariance stabilisation alpha of eq 30-31 (0 = divergence-free only)
    alpha: NonNegFloat = 0.01
    #: free-surface threshold N_surf of eq 34 (default: 48 in 3D as the seed, 17 in 2D)
    n_surf: Optional[PosInt] = None
    #: Dirichlet value at free-surface particles: zero (seed) or the hydrostatic pressure at the
    #: centre of a surface particle, rho_w |g| dx / 2 (the particle's top is the surface)
    free_surface_pressure: Literal["half_layer", "zero"] = "half_layer"
    #: free water (eps = 1) only: a particle below eq 34's count is free surface only if its number
    #: density <rho> is also below this fraction of rho_w (the MPS surface test of Koshizuka & Oka
    #: 1996, beta = 0.97). The count alone also flags particles inside the water whose outermost
    #: lattice ring (8 of 20 neighbours in 2D at 2.24 dx, r_e = 2.4 dx) has moved out; 0 = count only
    surface_density: Annotated[float, Field(ge=0, le=1)] = 0.97
    #: in and next to porous ground: a particle that eq 34's count (or, in free water, the plain
    #: particle count) finds short of neighbours is free surface only if no neighbour lies in a cone
    #: of this half-angle (degrees) about its outward normal, -sum_j V_j grad W_ij (the scan-region
    #: test of Marrone et al. 2010); 0 = eq 34's count alone (default). At 60 deg the permeameter's
    #: plug keeps no Dirichlet rows and its level holds at dt 1 and 0.5 ms, but the coarse free fall
    #: stops on the speed guard at 2.3 s (docs/isph.md, "Surface test in the ground")
    ground_surface_cone: Annotated[float, Field(ge=0, lt=90)] = 0.0
    #: pressure gradient: eq 12 difference form with kernel-gradient correction (default),
    #: plain eq 12, or the symmetric eq 13 form
    gradient: Literal["corrected", "difference", "symmetric"] = "corrected"
    #: near-contact collision model (MPS family): water particles closer than this fraction of dx
    #: lose their approaching relative velocity (walls: the velocity into the wall); 0 disables.
    #: Acts only on pairs far closer than the lattice spacing; its events are counted per step.
    collision_distance: Annotated[float, Field(ge=0, lt=1)] = 0.8
    #: coefficient of restitution of those collisions
    collision_restitution: Annotated[float, Field(ge=0, le=1)] = 0.2
    #: particle shifting against clustering (Fick's law, Lind et al. 2012 with Skillen et al. 2013's
    #: coefficient): dr = -A h |u| dt grad C, tangential only near the free surface; 0 disables
    shifting: NonNegFloat = 2.0
    #: largest shift per step, as a fraction of dx
    shifting_max: Annotated[float, Field(gt=0, le=0.5)] = 0.1
    ppe: PPESolver = PPESolver()
    #: particle motion inside the ground: pore (x moves with vD / eps, the physical reading of
    #: eq 15) or darcy (x moves with vD, the seed's literal reading)
    advection: Literal["pore", "darcy"] = "pore"


class WCSPHWater(Strict):
    """Water in mode wcsph_biot (its density and viscosity are `fluid.density` and `fluid.viscosity`)."""

    #: exponent gamma of the Tait equation of state eq 41
    gamma: PosFloat = 7.0
    #: sound speed c0 (m/s) of eq 41; default speed_factor x expected_speed, and with soil at least
    #: sqrt(20 M / rho_w), M the soil's constrained modulus (K_f = rho_w c0^2 >= 20 M: consolidation within
    #: 5 % of Terzaghi's c_v, docs/biot.md); a value below that logs a warning
    sound_speed: PosFloat | None = None
    #: c0 = speed_factor x expected_speed when sound_speed is not given (at least 10: density varies < 1 %)
    speed_factor: Annotated[float, Field(ge=10)] = 10.0
    #: largest flow speed expected (m/s); default sqrt(2 |g| H), H the height of the highest water or air
    #: block top above the tank floor (the free-fall speed from there)
    expected_speed: PosFloat | None = None
    #: pseudo surface tension eq 54 as a cohesion pressure P_c (Pa): the seed's a / m^2 = P_c / rho0^2,
    #: acting between particles of this material only; 0 = off
    cohesion: NonNegFloat = 0.0


class WCSPHAir(Strict):
    """Air in mode wcsph_biot: gas equation of state eq 39-40."""

    #: air density at the ambient pressure (kg/m^3) (seed: 1.207)
    density: PosFloat = 1.207
    #: kinematic viscosity (m^2/s) (seed: mu = 1.810e-5 Pa s, / 1.207 kg/m^3)
    viscosity: NonNegFloat = 1.5e-5
    #: ratio of specific heats gamma_gas of eq 40 (seed: 1.403)
    gamma: PosFloat = 1.403
    #: pseudo surface tension eq 54 as a cohesion pressure P_c (Pa), between air particles; 0 = off
    cohesion: NonNegFloat = 0.0


class ArtificialViscosity(Strict):
    """Monaghan artificial viscosity eq 36: Pi_ij = (-alpha c_ij mu_ij + beta mu_ij^2) / rho_ij for
    approaching pairs, mu_ij = h_ij v_ij . r_ij / (r_ij^2 + eps h_ij^2); between particles of one
    material and between fluid and wall particles."""

    #: alpha of eq 36 (seed: 0.001)
    alpha: NonNegFloat = 0.001
    #: beta of eq 36 (seed: 0)
    beta: NonNegFloat = 0.0
    #: eps_AF of eq 36 (seed: 0.1)
    eps: PosFloat = 0.1


class SoilBlock(Strict):
    """A block of soil particles (mode wcsph_biot): box, or a trapezoidal mound (levee) in the plane of
    the first and the vertical axis, across the whole tank along y in 3D. Water blocks may overlap it:
    their particles are then its pore water."""

    #: box: an axis-aligned block [min, max]; mound: a trapezoid with its base from toe[0] to toe[1] at
    #: height `bottom` and its crest from crest[0] to crest[1] at height `top`
    shape: Literal["box", "mound"] = "box"
    #: box corners (m)
    min: Optional[list[float]] = None
    max: Optional[list[float]] = None
    #: mound: [x_left, x_right] of its base and of its crest (m)
    toe: Optional[list[float]] = None
    crest: Optional[list[float]] = None
    #: mound: heights of its base and of its crest (m)
    bottom: float = 0.0
    top: Optional[float] = None
    #: hold this block's particles where they are (a rigid permeable base: water seeps through it, it
    #: carries the soil above it); as wcsph.soil.fixed for this block only. Where blocks overlap, the
    #: particles belong to the first block
    fixed: bool = False

    @model_validator(mode="after")
    def _shape_keys(self):
        if self.shape == "box":
            if self.min is None or self.max is None:
                raise ValueError("a box block needs min and max")
            Box(min=self.min, max=self.max)
        else:
            if self.toe is None or self.crest is None or self.top is None:
                raise ValueError("a mound block needs toe, crest and top")
            for key, pair in (("toe", self.toe), ("crest", self.crest)):
                if len(pair) != 2 or not pair[1] > pair[0]:
                    raise ValueError(f"{key} must be [x_left, x_right] with x_right > x_left")
            if not self.top > self.bottom:
                raise ValueError("top must exceed bottom")
            if self.crest[0] < self.toe[0] or self.crest[1] > self.toe[1]:
                raise ValueError("the crest must lie within the toe")
        return self

    def bounds(self, dim: int, tank_size) -> tuple[list[float], list[float]]:
        """Bounding box [lo, hi] (m)."""
        if self.shape == "box":
            return list(self.min), list(self.max)
        lo = [self.toe[0]] + ([0.0] if dim == 3 else []) + [self.bottom]
        hi = [self.toe[1]] + ([float(tank_size[1])] if dim == 3 else []) + [self.top]
        return lo, hi


class ExcessPorePressure(Strict):
    """Initial excess pore pressure u_e = amplitude sin(pi (y - bottom) / (top - bottom)) for bottom <= y <=
    top (y the vertical coordinate), added to the water's pressure inside the soil and taken from the
    soil's vertical effective stress (K0 times it from the horizontal), so the total stress is unchanged
    (seed 002 fig 10). The layer may reach below the tank floor: a layer drained at both faces is
    symmetric about its middle, which an impermeable floor can stand for. The soil starts at the settlement
    rate of Terzaghi's layer at t = 0+, v_s = (k / gamma_w) d u_e / dy along the vertical (the mixture's
    flux zero, as in a laterally confined layer over an impermeable base; docs/biot.md)."""

    #: largest excess pore pressure u0 (Pa)
    amplitude: float
    #: the layer's faces (m), where u_e = 0
    bottom: float
    top: float

    @model_validator(mode="after")
    def _ordered(self):
        if not self.top > self.bottom:
            raise ValueError("top must exceed bottom")
        return self


class SoilStartFrom(Strict):
    """The soil of an earlier run (a geostatic stage) as this run's start: positions, effective stress,
    plastic strain and density of its soil particles at one frame (docs/biot.md, two-stage runs). Both
    runs must build the same soil (soil_blocks, dx); water, air and walls come from this config."""

    #: run file of the earlier stage (completed, mode wcsph_biot); relative to the working directory
    run: str
    #: its frame to start from (Python index: -1 the last)
    frame: int = -1


class WCSPHSoil(Strict):
    """Soil of mode wcsph_biot (seed 002 sections 2.4 (2) and 2.5): elastic-perfectly-plastic effective
    stress (eq 42-45), compression positive; plane strain in 2D. Seed defaults."""

    #: initial porosity n0 (seed: 0.4); the soil particles' density is (1 - n) grain_density
    porosity: Annotated[float, Field(gt=0, lt=1)] = 0.4
    #: density of the grains rho_s (kg/m^3)
    grain_density: PosFloat = 2650.0
    #: reference Young's modulus E0 at the reference mean stress p0 of eq 42 (Pa) (seed: 150 MPa)
    youngs_modulus: PosFloat = 1.5e8
    #: reference mean effective stress p0 of eq 42 (Pa) (seed: 100 kPa)
    reference_stress: PosFloat = 1.0e5
    #: exponent m of eq 42 (seed: 0.5)
    exponent: NonNegFloat = 0.5
    #: floor of the mean effective stress used in eq 42 (Pa): E = E0 (max(p, floor) / p0)^m, so that soil
    #: at a free surface (p -> 0) keeps a stiffness and a sound speed
    stress_floor: PosFloat = 1000.0
    #: Poisson's ratio nu (seed: 0.3)
    poisson: Annotated[float, Field(gt=0, lt=0.5)] = 0.3
    #: Mohr-Coulomb friction angle phi (degrees): failure where the in-plane Mohr circle's radius reaches
    #: p sin(phi) + c cos(phi), p the in-plane mean effective stress (2D, plane strain); in 3D the
    #: Drucker-Prager cone sqrt(J2) = p sin(phi) + c cos(phi) that matches Mohr-Coulomb in plane strain
    #: (docs/biot.md). Give this or `tan_phi`, not both; default the seed's tan_phi = 0.5, i.e. 30 deg
    friction_angle: Annotated[float, Field(ge=0, lt=90)] | None = None
    #: the seed's form tau_f = p tan_phi on the Mohr circle's radius (seed 002 section 2.4 (2)), which is
    #: Mohr-Coulomb with sin(phi) = tan_phi: mapped to friction_angle = asin(tan_phi) (0.5 -> 30 deg, not
    #: atan(0.5) = 26.6 deg); at most 1. Give this or `friction_angle`, not both
    tan_phi: NonNegFloat | None = None
    #: Mohr-Coulomb cohesion c (Pa) (seed: none)
    cohesion: NonNegFloat = 0.0
    #: largest mean tension the soil carries (Pa, >= 0); beyond it the stress is set to zero (tension
    #: cut-off). Default: the tension at which the failure shear stress vanishes, c / tan(phi) (0 without
    #: cohesion)
    tension_cutoff: NonNegFloat | None = None
    #: initial ratio of horizontal to vertical effective stress K0; default nu / (1 - nu) (elastic, at rest)
    k0: PosFloat | None = None
    #: Monaghan artificial viscosity alpha of eq 36 between soil particles (seed: 0.001); c_ij the soil's
    #: P-wave speed
    alpha: NonNegFloat = 0.001
    #: permeability k of eq 46 (m/s) (hydraulic conductivity)
    permeability: PosFloat = 1.0e-3
    #: velocity damping of the soil (1/s): a_s -= damping v_s, for a geostatic stage (0 = off)
    damping: NonNegFloat = 0.0
    #: initial excess pore pressure (consolidation); none by default
    initial_excess_pressure: ExcessPorePressure | None = None
    #: start from the soil of an earlier run (two-stage runs: a geostatic stage, then the flood); none by
    #: default (K0 start)
    start_from: SoilStartFrom | None = None
    #: hold the soil particles where they are (a rigid porous skeleton: water seeps through it, the soil
    #: neither moves nor limits the time step); for steady-seepage checks
    fixed: bool = False

    def friction_angle_deg(self) -> float:
        """Mohr-Coulomb friction angle (degrees): `friction_angle`, or asin(tan_phi) (seed default 0.5)."""
        if self.friction_angle is not None:
            return self.friction_angle
        return math.degrees(math.asin(min(0.5 if self.tan_phi is None else self.tan_phi, 1.0)))

    def constrained_modulus(self, p: float) -> float:
        """Constrained (oedometric) modulus M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) at mean effective stress p
        (Pa), E of eq 42 (with the floor); in 2D the plane-strain P-wave modulus lambda + 2 G, the same value."""
        nu = self.poisson
        e = self.youngs_modulus * (max(p, self.stress_floor) / self.reference_stress) ** self.exponent
        return e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))


class InflowSource(Box):
    """River inflow (mode wcsph_biot): a source box above the river filled with water particles that are
    released row by row, lowest first, at a prescribed volume rate; they start at rest and fall into the
    river, whose level rises by rate / river width (docs/biot.md)."""

    #: volume of water released per second (m^2/s per metre of levee in 2D, m^3/s in 3D)
    rate: PosFloat
    #: time the release starts (s)
    start: NonNegFloat = 0.0


class WCSPH(Strict):
    """Options of mode wcsph_biot (weakly compressible SPH, seed 002)."""

    #: density: `normalised` advances it by continuity (eq 25 in the volume form of eq 48) and every
    #: `normalise_every` steps normalises it over particles of the same material (eq 27); `continuity`
    #: alone (a tank at rest then needs artificial_viscosity.alpha ~0.1: with the seed's 0.001 it goes unstable)
    density: Literal["normalised", "continuity"] = "normalised"
    #: steps between two applications of eq 27 (density: normalised)
    normalise_every: PosInt = 20
    #: initial water density: `hydrostatic` (from the weight of the fluid above each particle through the
    #: EOS, the run starts at rest in equilibrium) or `uniform` (fluid.density everywhere, as the seed's
    #: collapse cases). Air always starts at the density of the gas EOS at its depth.
    initial_density: Literal["hydrostatic", "uniform"] = "hydrostatic"
    #: ambient (absolute) pressure p0 above the free surface (Pa); pressures written are relative to it
    ambient_pressure: PosFloat = 1.0e5
    #: water equation of state and surface tension
    water: WCSPHWater = WCSPHWater()
    #: air properties
    air: WCSPHAir = WCSPHAir()
    #: artificial viscosity eq 36
    artificial_viscosity: ArtificialViscosity = ArtificialViscosity()
    #: XSPH coefficient eps_XSPH of eq 53 (0 = off); particles move with v - eps sum_j (m_j / rho_ij) v_ij W_ij
    #: over their fluid neighbours (air thus moves with the water around it)
    xsph: Annotated[float, Field(ge=0, le=1)] = 0.5
    #: variable smoothing length eq 52 (h follows the divergence; kept within [0.5, 1.1] h0)
    variable_h: bool = True
    #: upper bound beta_max of the boundary-particle factor beta of eq 51 (seed: 2)
    beta_max: Annotated[float, Field(ge=1)] = 2.0
    #: initial velocity: `right_face` gives the rightmost particle column of each water block the speed
    #: sqrt(2 |g| (H - y)) along +x, H the block top (seed section 3.1); `none` starts at rest
    release_velocity: Literal["none", "right_face"] = "none"
    #: neighbour lists hold pairs up to (1 + skin) x the support radius and are rebuilt only when some
    #: particle has moved far enough to need it (performance; results do not depend on it)
    neighbour_skin: Annotated[float, Field(ge=0, le=0.5)] = 0.2
    #: soil material (used when `soil_blocks` are given)
    soil: WCSPHSoil = WCSPHSoil()


class TimeStep(Strict):
    """Limits used when dt = auto: dt = min(cfl dx / u_max, viscous dx^2 / nu, force sqrt(dx / |g|)).
    Mode wcsph_biot uses the same three coefficients in its eq 49: dt = min(cfl h / c,
    force sqrt(h / |a|), viscous h^2 / nu) over all particles (h the smoothing length, c the sound speed)."""

    cfl: PosFloat = 0.25
    viscous: PosFloat = 0.125
    force: PosFloat = 0.25
    #: assumed speed (m/s) before the flow starts, e.g. sqrt(2 g H) for a collapse
    initial_speed: Optional[PosFloat] = None
    max: PosFloat = 0.005
    min: PosFloat = 1.0e-7


class Neighbours(Strict):
    #: neighbour-list capacity per particle; default 64 (2D) or 160 (3D). Overflow is an error.
    max: Optional[PosInt] = None


class Guard(Strict):
    """Stability checks made every step (speed, non-finite state) and every `every` steps and frame (the
    rest)."""

    #: stop when any speed exceeds this (m/s); default 20 sqrt(g H_domain)
    max_speed: Optional[PosFloat] = None
    #: particles leaving the domain: remove with a warning and count, or stop the run
    out_of_domain: Literal["remove", "error"] = "remove"
    #: water or air particles inside a wall (past a tank side or into an obstacle by more than dx / 2), found
    #: at the full checks: warn with their count whenever it changes (the run file's attribute
    #: `wall_crossings_max` keeps the most at one check), or stop the run (exit 6, the particles flagged)
    wall_crossing: Literal["warn", "error"] = "warn"
    #: full host-side check (non-finite state, density ratio, wall particles at rest) every this many steps
    #: and at every frame; speed and non-finite reductions are checked every step
    every: PosInt = 10
    #: stop when a water or air particle's density exceeds this multiple of its reference density; default
    #: 1.3 in mode wcsph_biot (Tait pressure ~6 B there) and 3 in mode isph (its number density reaches 1.6
    #: at the floor of a fine dam break that still runs well)
    max_density_ratio: PosFloat | None = None
    #: stop when a water or air particle's density falls below this multiple of its reference density
    #: (off by default: free-surface particles of mode isph have a low number density)
    min_density_ratio: PosFloat | None = None


class Checkpoint(Strict):
    """Restart points: the full solver state written to <run>.checkpoints/ beside the run file, read by
    `taichi-sph resume RUN.h5`. A run that completes always writes one at its end (so `taichi-sph resume
    RUN.h5 --set end_time=...` extends any finished run), and an interrupted run (Ctrl-C, SIGINT) one
    before it stops."""

    #: simulated seconds between checkpoints; none: only at the end of the run and when it is interrupted
    every: PosFloat | None = None
    #: how many of the newest checkpoints are kept (older ones are deleted)
    keep: PosInt = 2


#: per-step diagnostics a metric can read (run file /diagnostics/<name>)
MetricDiagnostic = Literal["kinetic_energy", "max_speed", "water_volume", "cg_iterations", "cg_residual", "dt",
                           "wall_seconds", "free_surface", "collisions"]


class Metric(Strict):
    """A number computed from a finished run (a probe or a diagnostic reduced over time), one column of
    the table `taichi-sph sweep` gathers. See docs/sweep.md."""

    #: column name in the sweep table (letters, digits and '_')
    name: ProbeName
    #: the time series it reads: a probe's name (probes[k].name) ...
    probe: str | None = None
    #: ... or a per-step diagnostic
    diagnostic: MetricDiagnostic | None = None
    #: for a velocity probe: component index (0 = x); default the speed (magnitude)
    component: Annotated[int, Field(ge=0, le=2)] | None = None
    #: final: last value; max, min; mean: time average (trapezoid); at: value at `time` (linear
    #: interpolation); first_above / first_below: first time (s) the series crosses `level` (interpolated)
    stat: Literal["final", "max", "min", "mean", "at", "first_above", "first_below"] = "final"
    #: for stat at: a time (s) or the name of an earlier metric whose value is a time
    time: NonNegFloat | str | None = None
    #: for stat first_above / first_below: the level, in the series' unit
    level: float | None = None


class Config(Strict):
    #: solver: isph (incompressible, PPE) or wcsph_biot (weakly compressible mixture)
    mode: Literal["isph", "wcsph_biot"] = "isph"
    #: number of space dimensions
    dim: Literal[2, 3] = 2
    #: initial particle spacing (m)
    dx: PosFloat
    #: simulated time (s)
    end_time: PosFloat
    #: time step (s) or auto (CFL-adaptive, see `timestep`). Mode wcsph_biot always takes the adaptive
    #: step of its eq 49 (limits `timestep.cfl`, `force`, `viscous`); a number caps that step
    dt: Union[PosFloat, Literal["auto"]] = 0.001
    #: Taichi backend
    arch: Literal["cpu", "cuda", "vulkan", "auto"] = "cpu"
    #: floating-point precision of fields (auto: f64 on CPU, f32 on GPUs)
    precision: Literal["auto", "f32", "f64"] = "auto"
    #: CPU threads (default: all cores)
    threads: Optional[PosInt] = None
    #: gravity vector (m/s^2); default -9.81 along the last axis
    gravity: Optional[list[float]] = None
    #: free text stored with the run
    description: str = ""
    #: run file and frame interval
    output: Output = Output()
    #: gauges sampled during the run (pressure at a point, water level, water volume or mean velocity in a box)
    probes: list[Probe] = []
    #: water properties
    fluid: Fluid = Fluid()
    #: the tank (required)
    tank: Tank
    #: water blocks (m), each filled with particles on a lattice of spacing dx (at least one, unless mode
    #: wcsph_biot has soil blocks)
    water: list[WaterBlock] = []
    #: solid blocks of wall particles inside the tank (m)
    obstacles: list[Obstacle] = []
    #: porous ground (mode isph): soil-marker regions and drag constants
    soil: Soil = Soil()
    #: options of mode isph
    isph: ISPH = ISPH()
    #: air blocks (m, fields as for `water`), mode wcsph_biot; they displace the water they overlap
    air: list[Box] = []
    #: options of mode wcsph_biot
    wcsph: WCSPH = WCSPH()
    #: soil particle blocks (m), mode wcsph_biot: a lattice of spacing dx overlapping any water block
    soil_blocks: list[SoilBlock] = []
    #: adaptive time-step limits (dt = auto)
    timestep: TimeStep = TimeStep()
    #: neighbour-list capacity
    neighbours: Neighbours = Neighbours()
    #: stability checks
    guard: Guard = Guard()
    #: named sets of dotted overrides applied by `--variant NAME`
    variants: dict[str, dict[str, object]] = {}
    #: checkpoints for `taichi-sph resume`
    checkpoint: Checkpoint = Checkpoint()
    #: numbers computed from the finished run, gathered by `taichi-sph sweep` (one column each)
    metrics: list[Metric] = []
    #: river inflow (mode wcsph_biot): source boxes of water released at a prescribed rate
    inflow: list[InflowSource] = []

    # ---- derived values -------------------------------------------------------------------
    def gravity_vector(self) -> list[float]:
        if self.gravity is not None:
            return list(self.gravity)
        g = [0.0] * self.dim
        g[-1] = -9.81
        return g

    def wall_layers(self) -> int:
        return self.tank.wall_layers or 3

    def n_surf(self) -> int:
        if self.isph.n_surf is not None:
            return self.isph.n_surf
        return 48 if self.dim == 3 else 17

    def max_neighbours(self) -> int:
        if self.neighbours.max is not None:
            return self.neighbours.max
        return 160 if self.dim == 3 else 64

    def expected_speed(self) -> float:
        """Largest flow speed expected in mode wcsph_biot (m/s): the key, or the free-fall speed from the
        highest water or air block top."""
        if self.wcsph.water.expected_speed is not None:
            return self.wcsph.water.expected_speed
        g = sum(c * c for c in self.gravity_vector()) ** 0.5
        top = max([box.max[-1] for box in [*self.water, *self.air, *self.inflow]]
                  + [blk.bounds(self.dim, self.tank.size)[1][-1] for blk in self.soil_blocks])
        return max((2.0 * g * top) ** 0.5, 1.0e-3)

    def soil_modulus(self) -> float | None:
        """Constrained modulus M of the soil (Pa) at the largest vertical effective stress of the scene, the
        dry weight of the highest soil top, (1 - n) rho_s |g| top (an upper bound of M where E grows with
        p); None without soil or with a rigid skeleton (`wcsph.soil.fixed`), which stores no water."""
        sp = self.wcsph.soil
        if self.mode != "wcsph_biot" or not self.soil_blocks or not self.water or sp.fixed:
            return None
        g = sum(c * c for c in self.gravity_vector()) ** 0.5
        top = max(blk.bounds(self.dim, self.tank.size)[1][-1] for blk in self.soil_blocks)
        return sp.constrained_modulus((1.0 - sp.porosity) * sp.grain_density * g * top)

    def pore_water_speed(self) -> float:
        """Sound speed at which the water's modulus K_f = rho_w c0^2 is PORE_WATER_STIFFNESS M (m/s; 0
        without soil): the storage 1 / K_f then slows consolidation by less than 5 % (docs/biot.md)."""
        m = self.soil_modulus()
        return 0.0 if m is None else (PORE_WATER_STIFFNESS * m / self.fluid.density) ** 0.5

    def sound_speed(self) -> float:
        """Sound speed c0 of the water equation of state (m/s), mode wcsph_biot: the key, or the larger of
        speed_factor x expected_speed and, with soil, `pore_water_speed`."""
        if self.wcsph.water.sound_speed is not None:
            return self.wcsph.water.sound_speed
        return max(self.wcsph.water.speed_factor * self.expected_speed(), self.pore_water_speed())


#: smallest ratio K_f / M of the water's EOS modulus to the soil's constrained modulus that the default
#: sound speed gives a scene with soil: the model's storage is 1 / K_f per mixture volume, so consolidation
#: runs with c_v = k / (gamma_w (1 / M + 1 / K_f)) = k M / gamma_w / (1 + M / K_f), 1 / 1.05 = 0.952 of the
#: physical value at 20 (docs/biot.md, "Storage and c_v")
PORE_WATER_STIFFNESS = 20.0


def check(cfg: "Config") -> None:
    """Cross-field rules; raises InputError naming the key."""
    d = cfg.dim
    _need_len(cfg.tank.size, d, "tank.size")
    if cfg.gravity is not None:
        _need_len(cfg.gravity, d, "gravity")
    for group in ("water", "obstacles"):
        for k, box in enumerate(getattr(cfg, group)):
            _need_len(box.min, d, f"{group}[{k}].min")
            _need_len(box.max, d, f"{group}[{k}].max")
            _inside(box, cfg.tank.size, f"{group}[{k}]")
    _check_motions(cfg)
    for k, reg in enumerate(cfg.soil.regions):
        key = f"soil.regions[{k}]"
        if reg.shape == "box":
            _need_len(reg.min, d, f"{key}.min")
            _need_len(reg.max, d, f"{key}.max")
            _inside(Box(min=reg.min, max=reg.max), cfg.tank.size, key)
        else:
            lo = [reg.toe[0]] + ([0.0] if d == 3 else []) + [reg.bottom]
            hi = [reg.toe[1]] + ([cfg.tank.size[1]] if d == 3 else []) + [reg.top]
            _inside(Box(min=lo, max=hi), cfg.tank.size, key)
    _check_pore_lattice(cfg)
    if cfg.soil.marker_spacing is not None and cfg.soil.marker_spacing > 2 * cfg.dx:
        _fail("soil.marker_spacing", f"must be at most 2 dx = {2 * cfg.dx} (markers must resolve the kernel)")
    _check_probes(cfg)
    _check_images(cfg)
    _check_metrics(cfg)
    _check_ppe(cfg)
    _check_periodic(cfg)
    if min(cfg.tank.size) < 2 * cfg.dx:
        _fail("tank.size", f"every side must hold at least 2 particles of dx = {cfg.dx}")
    for k, box in enumerate(cfg.air):
        _need_len(box.min, d, f"air[{k}].min")
        _need_len(box.max, d, f"air[{k}].max")
        _inside(box, cfg.tank.size, f"air[{k}]")
    _check_soil_blocks(cfg)
    _check_mode_sections(cfg)
    if isinstance(cfg.dt, float) and cfg.output.every < cfg.dt:
        _fail("output.every", f"must be at least dt = {cfg.dt}")
    if isinstance(cfg.dt, float) and cfg.dt >= cfg.end_time:
        _fail("dt", f"must be smaller than end_time = {cfg.end_time}")
    if cfg.timestep.min > cfg.timestep.max:
        _fail("timestep.min", "must not exceed timestep.max")


def _check_motions(cfg: "Config") -> None:
    """Moving obstacles: a constant velocity or an oscillation (amplitude and period), one value per
    axis, and stop after start."""
    for k, box in enumerate(cfg.obstacles):
        m = box.motion
        if m is None:
            continue
        key = f"obstacles[{k}].motion"
        if (m.velocity is None) == (m.amplitude is None):
            _fail(key, "give either velocity or amplitude (with period)")
        if m.velocity is not None:
            _need_len(m.velocity, cfg.dim, f"{key}.velocity")
            if m.period is not None:
                _fail(f"{key}.period", "belongs to an oscillation (amplitude), not to a constant velocity")
        else:
            _need_len(m.amplitude, cfg.dim, f"{key}.amplitude")
            if m.period is None:
                _fail(f"{key}.period", "is needed with amplitude")
        if m.stop is not None and m.stop <= m.start:
            _fail(f"{key}.stop", f"must be later than start = {m.start}")


def _fail(key: str, message: str):
    raise InputError(f"config key '{key}': {message}")


def _need_len(values, n, key):
    if len(values) != n:
        _fail(key, f"needs {n} values for dim = {n}, got {len(values)}")


def _inside(box: Box, size, key):
    tol = 1e-12
    for ax, (a, b, s) in enumerate(zip(box.min, box.max, size)):
        if a < -tol or b > s + tol:
            _fail(key, f"lies outside the tank interior [0, {s}] on axis {ax} (min={box.min}, max={box.max})")


def _check_probes(cfg: "Config") -> None:
    """Probe geometry matches the type, has `dim` values, lies inside the tank; names are unique."""
    geometry = {"pressure": "point", "water_level": "point", "water_volume": "box", "velocity": "box"}
    seen: dict[str, int] = {}
    for k, probe in enumerate(cfg.probes):
        key = f"probes[{k}]"
        columns = [probe.name]
        if probe.type == "velocity":
            columns += [f"{probe.name}_{a}" for a in "xyz"[: cfg.dim]]
        for col in columns:
            if col in seen:
                _fail(f"{key}.name", f"duplicate probe name '{col}' (also probes[{seen[col]}])")
            if col == "time":
                _fail(f"{key}.name", "'time' is reserved for the time column")
            seen[col] = k
        need = geometry[probe.type]
        other = "box" if need == "point" else "point"
        if getattr(probe, need) is None:
            _fail(f"{key}.{need}", f"required for a probe of type {probe.type}")
        if getattr(probe, other) is not None:
            _fail(f"{key}.{other}", f"not used by a probe of type {probe.type} (give {need})")
        if probe.point is not None:
            _need_len(probe.point, cfg.dim, f"{key}.point")
            for ax, (v, s) in enumerate(zip(probe.point, cfg.tank.size)):
                if not -1e-12 <= v <= s + 1e-12:
                    _fail(f"{key}.point", f"lies outside the tank interior [0, {s}] on axis {ax} "
                          f"(point={probe.point})")
        if probe.box is not None:
            _need_len(probe.box.min, cfg.dim, f"{key}.box.min")
            _need_len(probe.box.max, cfg.dim, f"{key}.box.max")
            _inside(probe.box, cfg.tank.size, f"{key}.box")
        if probe.every is not None and isinstance(cfg.dt, float) and probe.every < cfg.dt:
            _fail(f"{key}.every", f"must be at least dt = {cfg.dt}")


def _check_images(cfg: "Config") -> None:
    images = cfg.output.images
    if images is None:
        return
    if images.every < cfg.output.every:
        _fail("output.images.every", f"must be at least output.every = {cfg.output.every} (pictures are made from frames)")
    if len(images.size) != 2:
        _fail("output.images.size", f"needs 2 values [width, height], got {len(images.size)}")
    if max(images.size) > 8192:
        _fail("output.images.size", f"at most 8192 pixels a side, got {images.size}")
    if images.range is not None and (len(images.range) != 2 or not images.range[1] > images.range[0]):
        _fail("output.images.range", f"needs [lo, hi] with hi > lo, got {images.range}")
    if cfg.dim == 2 and images.camera not in ("auto", "front"):
        _fail("output.images.camera", f"a 2D run is drawn in its plane: use front or auto, not {images.camera}")
    if cfg.dim == 2 and images.field == "velocity_z":
        _fail("output.images.field", "a 2D run has no velocity_z (its axes are x and y)")


def _explicit_keys(model, prefix: str) -> list[str]:
    """Dotted names of the keys set explicitly (in the file, a variant or --set) inside a section."""
    out = []
    for name in model.model_fields_set:
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            inner = _explicit_keys(value, f"{prefix}.{name}")
            out.extend(inner or [f"{prefix}.{name}"])
        else:
            out.append(f"{prefix}.{name}")
    return sorted(out)


def periodic_cell(cfg: "Config") -> float:
    """Neighbour-search cell of the mode (m): the support radius 2.4 dx (isph), or 2 h_max plus the
    Verlet skin (wcsph_biot, h_max = 1.1 h0 with variable h)."""
    re = 2.4 * cfg.dx
    if cfg.mode == "isph":
        return re
    h_hi = (1.1 if cfg.wcsph.variable_h else 1.0) * 0.5 * re
    return 2.0 * h_hi + cfg.wcsph.neighbour_skin * re


def _check_periodic(cfg: "Config") -> None:
    """tank.periodic: valid distinct axes, each a whole number of dx long and at least 3 search cells;
    a Taylor-Green block needs a 2D doubly periodic tank."""
    per = cfg.tank.periodic
    if len(set(per)) != len(per):
        _fail("tank.periodic", f"lists an axis twice: {per}")
    cell = periodic_cell(cfg)
    for a in per:
        if not 0 <= a < cfg.dim:
            _fail("tank.periodic", f"axis {a} does not exist in {cfg.dim}D (axes 0 to {cfg.dim - 1})")
        L = cfg.tank.size[a]
        n = L / cfg.dx
        if abs(n - round(n)) > 1e-6 * max(1.0, n):
            _fail("tank.size", f"the period along periodic axis {a}, {L:g} m, must be a whole number of "
                  f"dx = {cfg.dx:g} (it is {n:.6g})")
        if L < 3.0 * cell:
            _fail("tank.size", f"the period along periodic axis {a}, {L:g} m, must hold 3 neighbour-search "
                  f"cells of {cell:.4g} m (at least {3.0 * cell:.4g} m)")
    for k, block in enumerate(cfg.water):
        if block.initial_velocity == "taylor_green" and (cfg.dim != 2 or sorted(per) != [0, 1]):
            _fail(f"water[{k}].initial_velocity", "taylor_green needs dim 2 and tank.periodic [0, 1]")


#: kernel support radius over dx, the same as taichi_sph.sph.kernels.SUPPORT_FACTOR (a test keeps them equal;
#: the schema does not import Taichi, so that bad input is reported before Taichi starts)
KERNEL_SUPPORT = 2.4


def _check_pore_lattice(cfg: Config) -> None:
    """Water in ground of porosity eps sits on a pore lattice of spacing dx eps^(-1/dim) (eq 33, constant
    particle mass). At or beyond the kernel support (2.4 dx) a particle there has no neighbour: its density
    and PPE row are empty and the first step gives NaN. Such a porosity cannot be resolved at any dx."""
    if cfg.mode != "isph":
        return
    floor = KERNEL_SUPPORT ** (-cfg.dim)
    why = (f"leaves water in the ground on a pore lattice of spacing dx eps^(-1/{cfg.dim}) at or beyond the "
           f"kernel support ({KERNEL_SUPPORT:g} dx), with no neighbours; it must be above {floor:.3f} in {cfg.dim}D")
    for k, reg in enumerate(cfg.soil.regions):
        if reg.eps0 <= floor:
            _fail(f"soil.regions[{k}].eps0", f"{reg.eps0:g} {why}")
    for k, block in enumerate(cfg.water):
        if block.porosity <= floor:
            _fail(f"water[{k}].porosity", f"{block.porosity:g} {why}")


def _check_mode_sections(cfg: Config) -> None:
    """Options of the other mode are errors rather than silently ignored."""
    if cfg.mode == "wcsph_biot":
        keys = _explicit_keys(cfg.isph, "isph") + _explicit_keys(cfg.soil, "soil")
        if keys:
            _fail(keys[0], "applies to mode isph only (mode is wcsph_biot)")
        for k, block in enumerate(cfg.water):
            if block.porosity != 1.0:
                _fail(f"water[{k}].porosity", "applies to mode isph only (mode is wcsph_biot)")
        if cfg.fluid.turbulence != "none":
            _fail("fluid.turbulence", f"{cfg.fluid.turbulence} is available in mode isph only")
        c0, u = cfg.sound_speed(), cfg.expected_speed()
        if cfg.wcsph.water.sound_speed is not None and c0 < 10.0 * u:
            _fail("wcsph.water.sound_speed", f"{c0:g} m/s is below 10 x the expected speed {u:.4g} m/s "
                  "(wcsph.water.expected_speed); density would vary by more than 1 %")
    else:
        keys = _explicit_keys(cfg.wcsph, "wcsph")
        if keys:
            _fail(keys[0], f"applies to mode wcsph_biot only (mode is {cfg.mode})")
        if cfg.air:
            _fail("air", f"air blocks need mode wcsph_biot (mode is {cfg.mode})")
        for k, block in enumerate(cfg.water):
            if block.start_head is not None:
                _fail(f"water[{k}].start_head", f"applies to mode wcsph_biot only (mode is {cfg.mode})")
            if block.inside_soil:
                _fail(f"water[{k}].inside_soil", f"applies to mode wcsph_biot only (mode is {cfg.mode})")


def _check_soil_blocks(cfg: "Config") -> None:
    """Soil blocks need mode wcsph_biot, `dim` values and must lie in the tank; water blocks are needed
    unless there is soil."""
    if not cfg.water and not (cfg.mode == "wcsph_biot" and cfg.soil_blocks):
        _fail("water", "needs at least one water block (mode wcsph_biot may have soil blocks instead)")
    if cfg.soil_blocks and cfg.mode != "wcsph_biot":
        _fail("soil_blocks", f"soil particles need mode wcsph_biot (mode is {cfg.mode}; mode isph has `soil`)")
    for k, blk in enumerate(cfg.soil_blocks):
        key = f"soil_blocks[{k}]"
        if blk.shape == "box":
            _need_len(blk.min, cfg.dim, f"{key}.min")
            _need_len(blk.max, cfg.dim, f"{key}.max")
        lo, hi = blk.bounds(cfg.dim, cfg.tank.size)
        _inside(Box(min=lo, max=hi), cfg.tank.size, key)
    for k, block in enumerate(cfg.water):
        if block.inside_soil and cfg.mode == "wcsph_biot":
            if not cfg.soil_blocks:
                _fail(f"water[{k}].inside_soil", "needs soil_blocks (the water fills their pores)")
            bounds = [blk.bounds(cfg.dim, cfg.tank.size) for blk in cfg.soil_blocks]
            if not any(all(a < sh and b > sl for a, b, sl, sh in zip(block.min, block.max, slo, shi))
                       for slo, shi in bounds):
                _fail(f"water[{k}].inside_soil", "the block overlaps no soil block (no pore to fill)")
    for k, src in enumerate(cfg.inflow):
        if cfg.mode != "wcsph_biot":
            _fail(f"inflow[{k}]", f"an inflow needs mode wcsph_biot (mode is {cfg.mode})")
        _need_len(src.min, cfg.dim, f"inflow[{k}].min")
        _need_len(src.max, cfg.dim, f"inflow[{k}].max")
        _inside(src, cfg.tank.size, f"inflow[{k}]")
    soil = cfg.wcsph.soil
    if soil.start_from is not None and not Path(soil.start_from.run).is_file():
        _fail("wcsph.soil.start_from.run", f"no run file '{soil.start_from.run}'")
    if soil.friction_angle is not None and soil.tan_phi is not None:
        _fail("wcsph.soil.tan_phi", "give either friction_angle (Mohr-Coulomb, degrees) or tan_phi (the seed's "
              "form, sin(phi) = tan_phi), not both")
    if soil.tan_phi is not None and soil.tan_phi > 1.0:
        _fail("wcsph.soil.tan_phi", f"{soil.tan_phi:g} exceeds 1: the seed's tau_f = p tan_phi is Mohr-Coulomb with "
              "sin(phi) = tan_phi, which has no angle above 1 (give friction_angle in degrees)")
    tan_mc = math.tan(math.radians(soil.friction_angle_deg()))
    if soil.tension_cutoff is not None and tan_mc > 0 and soil.tension_cutoff > soil.cohesion / tan_mc:
        _fail("wcsph.soil.tension_cutoff", f"must not exceed cohesion / tan(phi) = {soil.cohesion / tan_mc:g} Pa "
              "(beyond it the failure shear stress would be negative)")


def _check_metrics(cfg: "Config") -> None:
    """A metric reads exactly one series that exists, has the keys its stat needs, names are unique."""
    probes = {p.name: p for p in cfg.probes}
    seen: list[str] = []
    for k, m in enumerate(cfg.metrics):
        key = f"metrics[{k}]"
        if m.name in seen:
            _fail(f"{key}.name", f"duplicate metric name '{m.name}'")
        if (m.probe is None) == (m.diagnostic is None):
            _fail(key, "give exactly one of `probe` and `diagnostic`")
        if m.probe is not None and m.probe not in probes:
            _fail(f"{key}.probe", f"no probe named '{m.probe}' (probes: {', '.join(probes) or 'none'})")
        if m.component is not None and (m.probe is None or probes[m.probe].type != "velocity"):
            _fail(f"{key}.component", "applies to a velocity probe only")
        if m.component is not None and m.component >= cfg.dim:
            _fail(f"{key}.component", f"must be below dim = {cfg.dim}")
        if m.stat == "at":
            if m.time is None:
                _fail(f"{key}.time", "required for stat at")
            if isinstance(m.time, str) and m.time not in seen:
                _fail(f"{key}.time", f"'{m.time}' is neither a number nor the name of an earlier metric")
        elif m.time is not None:
            _fail(f"{key}.time", f"applies to stat at only (stat is {m.stat})")
        if m.stat in ("first_above", "first_below"):
            if m.level is None:
                _fail(f"{key}.level", f"required for stat {m.stat}")
        elif m.level is not None:
            _fail(f"{key}.level", f"applies to stats first_above and first_below only (stat is {m.stat})")
        seen.append(m.name)
#: relative residual below which an f32 conjugate gradient stalls (rounding of b - A x)
F32_PPE_TOLERANCE = 1.0e-5


def _check_ppe(cfg: Config) -> None:
    """isph.ppe: the ELL-only keys need type ell_pcg or mg_pcg; f32 cannot reach a tolerance below 1e-5."""
    ppe = cfg.isph.ppe
    if ppe.type not in ("ell_pcg", "mg_pcg"):
        for key in ("precision", "width"):
            if key in ppe.model_fields_set:
                _fail(f"isph.ppe.{key}", f"applies to isph.ppe.type ell_pcg and mg_pcg only (type is {ppe.type})")
    elif ppe.precision == "f32" and ppe.tolerance < F32_PPE_TOLERANCE:
        _fail("isph.ppe.precision", f"f32 conjugate gradient stalls near a relative residual of "
              f"{F32_PPE_TOLERANCE:g}; raise isph.ppe.tolerance ({ppe.tolerance:g}) or use f64")
