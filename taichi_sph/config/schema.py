"""Config schema: every key a case accepts, its default, its unit and its bounds.

All quantities are SI (m, s, kg, Pa). Vertical is the last axis (y in 2D, z in 3D) and gravity
points down it unless `gravity` says otherwise. The tank interior spans [0, size] on every axis;
walls are built outside it. Validation runs before any Taichi kernel is compiled. The sections live
in modules by concern: geometry.py (boxes, the box-or-mound shape, blocks, obstacles, tank), isph.py
(mode isph: porous ground, PPE), wcsph.py (mode wcsph_biot: equations of state, soil, inflow),
run_options.py (output, probes, time step, guard, checkpoints), sweep.py (metrics, the sweep file).
A case is `Config`, the union of `ISPHCase` and `WCSPHCase` told apart by `mode` (isph when it is left
out): each holds the keys every case accepts (`_Case`) and its mode's own sections, so a key of the
other mode is an error of the schema itself. Each cross-field rule is a validator on the model that owns
its keys (a section's own rules on the section; rules that need dim, the tank or the mode on the case
model, its `_rules`). Keys are documented in docs/config.md; `taichi-sph schema` prints the JSON Schema.
"""

from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Discriminator, Tag, TypeAdapter, model_validator

from .base import NonNegFloat, PosFloat, PosInt, Strict, fail
from .geometry import (  # noqa: F401  (re-exported: `from taichi_sph.config.schema import ...`)
    AirBlock,
    Box,
    Obstacle,
    ObstacleMotion,
    Shape,
    Tank,
    WaterBlock,
    check_box,
    check_geometry,
    check_periodic,
    check_tank_room,
    periodic_cell,
)
from .isph import F32_PPE_TOLERANCE, ISPH, PPESolver, Soil, SoilRegion, check_ground  # noqa: F401
from .run_options import (  # noqa: F401
    Checkpoint,
    Guard,
    ImageField,
    Images,
    Neighbours,
    Output,
    Probe,
    ProbeName,
    TimeStep,
    check_images,
    check_probes,
    check_times,
)
from .sweep import Metric, MetricDiagnostic, check_metrics  # noqa: F401
from .wcsph import (  # noqa: F401
    DENSITY_DIFFUSION_RAISED,
    PORE_WATER_STIFFNESS,
    WCSPH,
    ArtificialViscosity,
    ExcessPorePressure,
    InflowSource,
    SoilBlock,
    SoilStartFrom,
    WCSPHAir,
    WCSPHSoil,
    WCSPHWater,
    check_soil_blocks,
)


class Fluid(Strict):
    #: water density rho_w (kg/m^3)
    density: PosFloat = 1000.0
    #: kinematic viscosity nu_w (m^2/s)
    viscosity: NonNegFloat = 1.0e-6
    #: sub-particle turbulence: Smagorinsky eddy viscosity nu_T = (Cs Delta)^2 |S| (seed 000 eq 3), between
    #: water particles; the walls' shear takes the water's own viscosity (the model has no wall damping,
    #: docs/isph.md "No eddy viscosity in the wall's shear")
    turbulence: Literal["none", "smagorinsky"] = "none"
    smagorinsky_cs: PosFloat = 0.2


class _Case(Strict):
    """Keys every case accepts, whatever its mode; `ISPHCase` and `WCSPHCase` add their mode's own."""

    #: solver: isph (incompressible, PPE) or wcsph_biot (weakly compressible mixture)
    mode: str = "isph"
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
    #: floating-point precision of fields (auto: f32 on GPUs and in mode wcsph_biot, whose positions, density
    #: and h stay f64; f64 for mode isph on the CPU; a resumed run keeps its run file's)
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

    #: the cross-field rules of the mode, in order (each raises base.fail naming the key)
    _rules = ()

    @model_validator(mode="after")
    def _cross_field_rules(self):
        """The rules that need keys of more than one section (after every section's own rules)."""
        for rule in self._rules:
            rule(self)
        return self

    # ---- derived values -------------------------------------------------------------------
    def gravity_vector(self) -> list[float]:
        if self.gravity is not None:
            return list(self.gravity)
        g = [0.0] * self.dim
        g[-1] = -9.81
        return g

    def wall_layers(self) -> int:
        return self.tank.wall_layers or 3

    def max_neighbours(self) -> int:
        if self.neighbours.max is not None:
            return self.neighbours.max
        return 160 if self.dim == 3 else 64


class ISPHCase(_Case):
    """A case of mode isph: water over and through porous ground given by soil markers (seed 000)."""

    #: solver: isph (incompressible, PPE) or wcsph_biot (weakly compressible mixture)
    mode: Literal["isph"] = "isph"
    #: porous ground: soil-marker regions and drag constants
    soil: Soil = Soil()
    #: options of mode isph
    isph: ISPH = ISPH()

    def n_surf(self) -> int:
        if self.isph.n_surf is not None:
            return self.isph.n_surf
        return 48 if self.dim == 3 else 17


class WCSPHCase(_Case):
    """A case of mode wcsph_biot: water, air and soil as overlapping particle sets (seed 002)."""

    #: solver: isph (incompressible, PPE) or wcsph_biot (weakly compressible mixture)
    mode: Literal["wcsph_biot"]
    #: air blocks (m): min, max and, as water blocks, inside_soil / outside_soil; they displace the water
    #: they overlap
    air: list[AirBlock] = []
    #: options of mode wcsph_biot
    wcsph: WCSPH = WCSPH()
    #: soil particle blocks (m): a lattice of spacing dx overlapping any water block
    soil_blocks: list[SoilBlock] = []
    #: river inflow: source boxes of water released at a prescribed rate
    inflow: list[InflowSource] = []

    def expected_speed(self) -> float:
        """Largest flow speed expected (m/s): the key, or the free-fall speed from the highest water or air
        block top."""
        if self.wcsph.water.expected_speed is not None:
            return self.wcsph.water.expected_speed
        g = sum(c * c for c in self.gravity_vector()) ** 0.5
        top = max([box.max[-1] for box in [*self.water, *self.air, *self.inflow]]
                  + [blk.bounds(self.dim, self.tank.size)[1][-1] for blk in self.soil_blocks])
        return max((2.0 * g * top) ** 0.5, 1.0e-3)

    def air_conductivity(self) -> float | None:
        """The soil's conductivity for air (m/s) of the air-soil drag (eq 46 with rho_f the air's):
        `wcsph.soil.air_permeability`, or k nu_w / nu_a (the same intrinsic permeability K = k nu_w / g);
        None (no drag) for air of zero viscosity left to the default."""
        sp = self.wcsph.soil
        if sp.air_permeability is not None:
            return sp.air_permeability
        if self.wcsph.air.viscosity <= 0.0:
            return None
        return sp.permeability * self.fluid.viscosity / self.wcsph.air.viscosity

    def soil_modulus(self) -> float | None:
        """Constrained modulus M of the soil (Pa) at the largest vertical effective stress of the scene, the
        dry weight of the highest soil top, (1 - n) rho_s |g| top (an upper bound of M where E grows with
        p); None without soil or with a rigid skeleton (`wcsph.soil.fixed`), which stores no water."""
        sp = self.wcsph.soil
        if not self.soil_blocks or not self.water or sp.fixed:
            return None
        g = sum(c * c for c in self.gravity_vector()) ** 0.5
        top = max(blk.bounds(self.dim, self.tank.size)[1][-1] for blk in self.soil_blocks)
        return sp.constrained_modulus((1.0 - sp.porosity) * sp.grain_density * g * top)

    def pore_storage(self) -> float:
        """The share S of the mixture's volume the pore water's particles fill: 1 (`wcsph.soil.pore_water`
        full_volume), or the porosity n (pore_volume); the pore water's storage is S / K_f (docs/biot.md)."""
        sp = self.wcsph.soil
        return sp.porosity if sp.pore_water == "pore_volume" else 1.0

    def pore_water_speed(self) -> float:
        """Sound speed at which the water's modulus K_f = rho_w c0^2 is PORE_WATER_STIFFNESS S M (m/s; 0
        without soil; S the `pore_storage`): the storage S / K_f then slows consolidation by 2.5 % at most
        (docs/biot.md)."""
        m = self.soil_modulus()
        return 0.0 if m is None else (PORE_WATER_STIFFNESS * self.pore_storage() * m / self.fluid.density) ** 0.5

    def sound_speed(self) -> float:
        """Sound speed c0 of the water equation of state (m/s): the key, or the larger of speed_factor x
        expected_speed and, with soil, `pore_water_speed`."""
        if self.wcsph.water.sound_speed is not None:
            return self.wcsph.water.sound_speed
        return max(self.flow_sound_speed(), self.pore_water_speed())

    def flow_sound_speed(self) -> float:
        """The sound speed the flow alone needs (m/s): speed_factor x expected_speed."""
        return self.wcsph.water.speed_factor * self.expected_speed()

    def viscosity_speed(self) -> float:
        """The water's c_ij of the artificial viscosity eq 36 (m/s): `wcsph.artificial_viscosity.speed`, or
        the c0 given (`wcsph.water.sound_speed`), or the flow's sound speed where c0 is left to its default
        (which soil raises above it: eq 36 at the raised c0 is a shear viscosity 20x the flow's)."""
        if self.wcsph.artificial_viscosity.speed is not None:
            return self.wcsph.artificial_viscosity.speed
        if self.wcsph.water.sound_speed is not None:
            return self.sound_speed()
        return self.flow_sound_speed()

    def raised_sound_speed(self) -> bool:
        """Soil raised c0 above the flow's sound speed (c0 left to its default)."""
        return self.wcsph.water.sound_speed is None and self.pore_water_speed() > self.flow_sound_speed()

    def density_diffusion(self) -> float:
        """delta of the water's density diffusion: `wcsph.density_diffusion`, or 0.1 where soil raised c0
        (`raised_sound_speed`), else 0."""
        if self.wcsph.density_diffusion is not None:
            return self.wcsph.density_diffusion
        return DENSITY_DIFFUSION_RAISED if self.raised_sound_speed() else 0.0


def check_isph_water(cfg: ISPHCase) -> None:
    """At least one water block; the keys of water blocks (and the guard's) that only mode wcsph_biot reads
    are errors."""
    if not cfg.water:
        fail("water", "needs at least one water block (mode wcsph_biot may have soil blocks instead)")
    for k, block in enumerate(cfg.water):
        for key in ("start_head", "inside_soil", "outside_soil"):
            if getattr(block, key) not in (None, False):
                fail(f"water[{k}].{key}", f"applies to mode wcsph_biot only (mode is {cfg.mode})")
    if cfg.guard.max_pore_pressure is not None:  # mode isph's soil markers carry no pore pressure
        fail("guard.max_pore_pressure", f"applies to mode wcsph_biot only (mode is {cfg.mode})")


def check_wcsph_fluids(cfg: WCSPHCase) -> None:
    """Air blocks inside the tank; no porosity or turbulence (mode isph only); a sound speed given
    explicitly at least 10 x the expected speed."""
    for k, box in enumerate(cfg.air):
        check_box(box, cfg.dim, cfg.tank.size, f"air[{k}]")
    for k, block in enumerate(cfg.water):
        if block.porosity != 1.0:
            fail(f"water[{k}].porosity", "applies to mode isph only (mode is wcsph_biot)")
    if cfg.fluid.turbulence != "none":
        fail("fluid.turbulence", f"{cfg.fluid.turbulence} is available in mode isph only")
    if cfg.air and cfg.soil_blocks and cfg.air_conductivity() == 0.0:  # the default with water of no viscosity
        fail("wcsph.soil.air_permeability", "needed with air and soil and fluid.viscosity 0: the default k nu_w "
             "/ nu_a would stop the air dead in the pores")
    c0, u = cfg.sound_speed(), cfg.expected_speed()
    if cfg.wcsph.water.sound_speed is not None and c0 < 10.0 * u:
        fail("wcsph.water.sound_speed", f"{c0:g} m/s is below 10 x the expected speed {u:.4g} m/s "
             "(wcsph.water.expected_speed); density would vary by more than 1 %")


ISPHCase._rules = (check_geometry, check_ground, check_probes, check_images, check_metrics, check_periodic,
                   check_tank_room, check_isph_water, check_times)
WCSPHCase._rules = (check_geometry, check_probes, check_images, check_metrics, check_periodic, check_tank_room,
                    check_wcsph_fluids, check_soil_blocks, check_times)

#: the sections each mode alone has (a case of the other mode may not set them)
MODE_SECTIONS = {"isph": ("soil", "isph"), "wcsph_biot": ("air", "wcsph", "soil_blocks", "inflow")}
#: the case model of each mode
CASES = {"isph": ISPHCase, "wcsph_biot": WCSPHCase}


def _mode_of(value) -> str | None:
    """The discriminator of Config: a case's `mode` (isph when the key is left out)."""
    if isinstance(value, dict):
        return value.get("mode", "isph")
    return getattr(value, "mode", None)


#: a case file: ISPHCase or WCSPHCase, told apart by `mode`
Config = Annotated[Union[Annotated[ISPHCase, Tag("isph")], Annotated[WCSPHCase, Tag("wcsph_biot")]],
                   Discriminator(_mode_of)]
#: validates a case (`CONFIG.validate_python(data)`) and gives its JSON Schema
CONFIG = TypeAdapter(Config)


#: JSON Schema dialect of `json_schema` (pydantic writes draft 2020-12)
JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


def json_schema() -> dict:
    """The JSON Schema of a case file (`taichi-sph schema`, docs/config.schema.json), for editors that
    complete and check YAML. It holds each key's type, range and default; the cross-field rules (lengths
    equal to dim, blocks inside the tank, options of the other mode) are checked by `taichi-sph --check`."""
    return {"$schema": JSON_SCHEMA_DIALECT, **CONFIG.json_schema(), "title": "taichi-sph case file"}
