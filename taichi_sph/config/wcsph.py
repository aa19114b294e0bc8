"""Options of mode wcsph_biot (seed 002): the water's and the air's equations of state, artificial
viscosity, the soil (its blocks, material, initial excess pore pressure, start from an earlier stage),
the river inflow; and the rules on soil blocks and inflows that need the tank and the water
(`check_soil_blocks`, run by Config)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, ClassVar, Literal, Optional

from pydantic import Field, model_validator

from .base import NonNegFloat, PosFloat, PosInt, Strict, fail, inside, need_len
from .geometry import Box, Shape, check_box

#: smallest ratio K_f / M of the water's EOS modulus to the soil's constrained modulus that the default
#: sound speed gives a scene with soil: the model's storage is 1 / K_f per mixture volume, so consolidation
#: runs with c_v = k M / gamma_w / (1 + M / K_f) and a sudden load goes to the pore water by Skempton's
#: B = 1 / (1 + M / K_f): 1 / 1.025 = 0.976 at 40 (0.952 at 20 left the undrained ratio at 0.944-0.948,
#: short of 0.95; docs/biot.md, "Storage and c_v" and "Undrained loading")
PORE_WATER_STIFFNESS = 40.0
#: wcsph.density_diffusion when not given, in a scene whose c0 soil raised above the flow's sound speed:
#: with eq 36 then at the flow's sound speed (artificial_viscosity.speed), the pore water's acoustic modes
#: need this damping (at dx 0.01 a levee's burst without it); 0.1 is the usual delta-SPH value and, in the
#: gradient form, leaves the undrained and consolidation checks as without it (docs/biot.md, "Artificial
#: viscosity and the pore water's sound speed")
DENSITY_DIFFUSION_RAISED = 0.1


class WCSPHWater(Strict):
    """Water in mode wcsph_biot (its density and viscosity are `fluid.density` and `fluid.viscosity`)."""

    #: exponent gamma of the Tait equation of state eq 41
    gamma: PosFloat = 7.0
    #: sound speed c0 (m/s) of eq 41; default speed_factor x expected_speed, and with soil at least
    #: sqrt(40 M / rho_w), M the soil's constrained modulus (K_f = rho_w c0^2 >= 40 M: consolidation within
    #: 2.5 % of Terzaghi's c_v, a sudden load 0.976 in the pore water, docs/biot.md); a value below that logs
    #: a warning
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
    #: the water's c_ij of eq 36 (m/s); default the c0 given (wcsph.water.sound_speed), or, where c0 is left
    #: to its default, the flow's sound speed speed_factor x expected_speed. Its shear viscosity alpha c h /
    #: 8 grows with c: at the c0 that soil raises to the pore water's stiffness (~350 m/s at a levee, 20x the
    #: flow's) it slowed the levee's seepage to 0.73x (docs/biot.md, "Artificial viscosity and the pore
    #: water's sound speed"). Air uses its own c.
    speed: PosFloat | None = None


class SoilBlock(Shape):
    """A block of soil particles (mode wcsph_biot): box, or a trapezoidal mound (levee) in the plane of
    the first and the vertical axis, across the whole tank along y in 3D (`Shape`). Water blocks may
    overlap it: their particles are then its pore water."""

    _noun: ClassVar[str] = "block"

    #: hold this block's particles where they are (a rigid permeable base: water seeps through it, it
    #: carries the soil above it); as wcsph.soil.fixed for this block only. Where blocks overlap, the
    #: particles belong to the first block
    fixed: bool = False


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

    @model_validator(mode="after")
    def _run_exists(self):
        if not Path(self.run).is_file():
            fail("run", f"no run file '{self.run}'")
        return self


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
    #: dilatancy angle psi (degrees) of the plastic flow: plastic volume grows at sin(psi) times the plastic
    #: shear strain rate. 0 (default): no plastic volume change, a layer in steady simple shear slides at
    #: tan(phi*) = sin(phi), below phi; psi = phi (associated flow): it slides at phi, dilating while it
    #: slides (Davis 1968; docs/biot.md). At most the friction angle
    dilatancy_angle: Annotated[float, Field(ge=0, lt=90)] = 0.0
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
    #: the soil's conductivity for air (m/s): k of eq 46 between soil and air particles, with the air's
    #: density for rho_f (the seed's air permeability). Default: the same pores as `permeability`, whose
    #: intrinsic permeability K = k nu_w / g gives K g / nu_a = k nu_w / nu_a (1/15 of k for water and air
    #: at 20 C); no drag on air of zero viscosity
    air_permeability: PosFloat | None = None
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
    #: what a water particle inside the soil stands for (docs/biot.md, "Pore water at its own volume"):
    #: `full_volume` (the seed's overlapping sets: it fills the mixture's volume and moves with u = n v_f +
    #: (1 - n) v_s, so a rising phreatic line stores 1 m^3 of water per m^3 of soil) or `pore_volume` (it
    #: fills the pores only: partial density n rho_w, the pore velocity v_f, a storage of n per unit rise,
    #: as a sand's); `pore_volume` needs `wcsph.density: continuity` and no air blocks
    pore_water: Literal["full_volume", "pore_volume"] = "full_volume"

    @model_validator(mode="after")
    def _failure_keys(self):
        """One form of the friction angle; a tension cut-off below the tension where the failure shear
        stress vanishes."""
        if self.friction_angle is not None and self.tan_phi is not None:
            fail("tan_phi", "give either friction_angle (Mohr-Coulomb, degrees) or tan_phi (the seed's "
                 "form, sin(phi) = tan_phi), not both")
        if self.tan_phi is not None and self.tan_phi > 1.0:
            fail("tan_phi", f"{self.tan_phi:g} exceeds 1: the seed's tau_f = p tan_phi is Mohr-Coulomb with "
                 "sin(phi) = tan_phi, which has no angle above 1 (give friction_angle in degrees)")
        if self.dilatancy_angle > self.friction_angle_deg() + 1e-12:
            fail("dilatancy_angle", f"{self.dilatancy_angle:g} deg exceeds the friction angle "
                 f"{self.friction_angle_deg():g} deg (psi = phi is the associated flow rule)")
        tan_mc = math.tan(math.radians(self.friction_angle_deg()))
        if self.tension_cutoff is not None and tan_mc > 0 and self.tension_cutoff > self.cohesion / tan_mc:
            fail("tension_cutoff", f"must not exceed cohesion / tan(phi) = {self.cohesion / tan_mc:g} Pa "
                 "(beyond it the failure shear stress would be negative)")
        return self

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

    #: volume of water released per second (m^2/s per metre of levee in 2D, m^3/s in 3D); with `level`,
    #: the rate while the river is below its target level
    rate: PosFloat
    #: time the release starts (s)
    start: NonNegFloat = 0.0
    #: target river level history [[t, z], ...] (s, m; times increasing, linear between, held after the
    #: last): the source releases at `rate` while the river, read by the probe `level_probe`, is below
    #: the target, and holds while it is at or above it (a river held at a level, or rising at a rate)
    level: Optional[list[list[float]]] = None
    #: name of a `water_level` probe (in `probes`) that reads the river level for `level`; its `every`
    #: is the control interval, and its samples are the run's level-time history
    level_probe: Optional[str] = None
    #: the gate compares the mean of the probe's readings over this many seconds (a stilling well: the
    #: waves that the falling stream raises swing a single reading); 0 = the last reading
    level_smoothing: NonNegFloat = 0.0

    @model_validator(mode="after")
    def _level_pair(self):
        """`level` and `level_probe` come together; the target's times increase."""
        if (self.level is None) != (self.level_probe is None):
            have, need = ("level", "level_probe") if self.level is not None else ("level_probe", "level")
            fail(need, f"required with `{have}` (a target level history and the probe that reads it)")
        if self.level is not None:
            if not self.level:
                fail("level", "needs at least one [t, z] point")
            for k, point in enumerate(self.level):
                if len(point) != 2 or point[0] < 0:
                    fail(f"level[{k}]", f"needs [t, z] with t >= 0 (got {point})")
            times = [t for t, _ in self.level]
            if any(b <= a for a, b in zip(times, times[1:])):
                fail("level", f"times must increase (got {times})")
        return self


class WCSPH(Strict):
    """Options of mode wcsph_biot (weakly compressible SPH, seed 002)."""

    #: density: `normalised` advances it by continuity (eq 25 in the volume form of eq 48) and every
    #: `normalise_every` steps normalises it over particles of the same material (eq 27); `continuity`
    #: alone (a tank at rest then needs artificial_viscosity.alpha ~0.1: with the seed's 0.001 it goes unstable)
    density: Literal["normalised", "continuity"] = "normalised"
    #: steps between two applications of eq 27 (density: normalised)
    normalise_every: PosInt = 20
    #: density diffusion delta of the water (delta-SPH, Molteni & Colagrossi 2009, with the hydrostatic
    #: part taken out as Fourtakas et al. 2019): d rho_i / dt += delta h c0 sum_j 2 (rho_j - rho_i -
    #: rho^H_ji) (x_j - x_i) . grad_i W_ij / |x_ij|^2 V_j between water particles, rho^H_ji = rho_w g .
    #: (x_j - x_i) / c0^2 (less the gradient correction of density_diffusion_form); 0 = off. It damps the
    #: water's acoustic noise at the rate of c0 without the shear viscosity of eq 36. Default 0.1 where soil
    #: raised c0 above the flow's sound speed (there eq 36 takes the flow's sound speed, and the pore water's
    #: acoustic modes need it), else 0 (docs/biot.md, "Artificial viscosity and the pore water's sound speed")
    density_diffusion: NonNegFloat | None = None
    #: the difference the density diffusion acts on: `hydrostatic`, rho_j - rho_i - rho^H_ji (Fourtakas et
    #: al. 2019), a Laplacian: inside soil it consolidates the pore pressure at delta h c0; `gradient`, that
    #: difference less (G_i + G_j) . (x_j - x_i) / 2 with G the renormalised gradient of rho - rho^H from the
    #: last pair pass (Antuono et al. 2010), which vanishes on a linear field: a fourth-order damping that
    #: leaves a smooth pore-pressure field (wavelength L) alone to order (h / L)^2 and still damps the
    #: particle-scale noise (docs/biot.md, "Density diffusion with the gradient correction")
    density_diffusion_form: Literal["hydrostatic", "gradient"] = "gradient"
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


def check_soil_blocks(cfg) -> None:
    """Soil blocks have `dim` values and lie in the tank; water blocks are needed unless there is soil;
    water or air inside soil needs soil to fill, outside it soil to keep out of; inflows lie in the tank (a
    case of mode wcsph_biot)."""
    if not cfg.water and not cfg.soil_blocks:
        fail("water", "needs at least one water block (mode wcsph_biot may have soil blocks instead)")
    for k, blk in enumerate(cfg.soil_blocks):
        blk.check_in_tank(cfg.dim, cfg.tank.size, f"soil_blocks[{k}]")
    for name, blocks in (("water", cfg.water), ("air", cfg.air)):
        for k, block in enumerate(blocks):
            if block.outside_soil and not cfg.soil_blocks:
                fail(f"{name}[{k}].outside_soil", f"needs soil_blocks (the {name} is kept out of them)")
            if block.inside_soil:
                if not cfg.soil_blocks:
                    fail(f"{name}[{k}].inside_soil", f"needs soil_blocks (the {name} fills their pores)")
                bounds = [blk.bounds(cfg.dim, cfg.tank.size) for blk in cfg.soil_blocks]
                if not any(all(a < sh and b > sl for a, b, sl, sh in zip(block.min, block.max, slo, shi))
                           for slo, shi in bounds):
                    fail(f"{name}[{k}].inside_soil", "the block overlaps no soil block (no pore to fill)")
    if cfg.wcsph.soil.pore_water == "pore_volume":
        if cfg.wcsph.density != "continuity":
            fail("wcsph.soil.pore_water", "pore_volume needs wcsph.density: continuity (eq 27 would average "
                 "the pore water's density with the free water's across the soil's surface)")
        if cfg.air:
            fail("wcsph.soil.pore_water", "pore_volume takes no air blocks (air in the pores at the mixture's "
                 "volume beside pore water at its own is not built)")
    for k, src in enumerate(cfg.inflow):
        check_box(src, cfg.dim, cfg.tank.size, f"inflow[{k}]")
        if src.level_probe is not None:
            probe = next((p for p in cfg.probes if p.name == src.level_probe), None)
            if probe is None or probe.type != "water_level":
                fail(f"inflow[{k}].level_probe",
                     f"names no water_level probe in `probes` ({src.level_probe!r})")
