"""Geometry of a case: boxes, the box-or-mound shape shared by the soil regions of mode isph and the
soil blocks of mode wcsph_biot, water blocks, obstacles and their motion, the tank; and the rules that
place them in the tank (`check_geometry`, `check_periodic`, run by Config)."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Optional

import numpy as np
from pydantic import Field, model_validator

from ..sph.support import SUPPORT_FACTOR
from .base import NonNegFloat, PosFloat, PosInt, Strict, fail, inside, need_len


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


class Shape(Strict):
    """A box, or a trapezoidal mound in the plane of the first and the vertical axis, across the whole
    tank along y in 3D (soil regions of mode isph and soil blocks of mode wcsph_biot)."""

    #: what the shape is called in messages
    _noun: ClassVar[str] = "shape"

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

    @model_validator(mode="after")
    def _shape_keys(self):
        if self.shape == "box":
            if self.min is None or self.max is None:
                raise ValueError(f"a box {self._noun} needs min and max")
            Box(min=self.min, max=self.max)
        else:
            if self.toe is None or self.crest is None or self.top is None:
                raise ValueError(f"a mound {self._noun} needs toe, crest and top")
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

    def check_in_tank(self, dim: int, tank_size, key: str) -> None:
        """A box has dim values per corner; the shape lies in the tank."""
        if self.shape == "box":
            need_len(self.min, dim, f"{key}.min")
            need_len(self.max, dim, f"{key}.max")
        inside(*self.bounds(dim, tank_size), tank_size, key)


class SoilSideBlock(Box):
    """A block of fluid particles (m) that mode wcsph_biot may cut to the soil blocks' inside or outside."""

    #: mode wcsph_biot: keep only the block's lattice points inside soil blocks, so that the block
    #: fills the pores of the ground up to its top (a levee saturated up to a phreatic level, or the air
    #: in a dry levee's pores) and leaves the open ground above and beside the soil empty; needs
    #: `soil_blocks`
    inside_soil: bool = False
    #: mode wcsph_biot: keep only the block's lattice points outside soil blocks (open water beside
    #: ground whose pores stay dry: a river against a dry levee); needs `soil_blocks`
    outside_soil: bool = False

    @model_validator(mode="after")
    def _one_soil_side(self):
        if self.inside_soil and self.outside_soil:
            fail("outside_soil", "a block fills the soil's pores (inside_soil) or the space outside it, not both")
        return self


class AirBlock(SoilSideBlock):
    """A block of air particles (m, mode wcsph_biot); they displace the water they overlap."""


class WaterBlock(SoilSideBlock):
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
    #: a water table [[x, z], ...] (m): keep only the block's lattice points at or below this polyline,
    #: heights z at positions x along the first axis, linear between points and level beyond the ends
    #: (a levee's phreatic line that falls from the river to the landside floor); default none (the box)
    table: Optional[list[list[float]]] = None

    @model_validator(mode="after")
    def _table_points(self):
        """The water table has at least two [x, z] points with x increasing."""
        if self.table is not None:
            if len(self.table) < 2:
                fail("table", f"needs at least two [x, z] points (got {len(self.table)})")
            for k, point in enumerate(self.table):
                if len(point) != 2:
                    fail(f"table[{k}]", f"needs [x, z] (got {point})")
            xs = [x for x, _ in self.table]
            if any(b <= a for a, b in zip(xs, xs[1:])):
                fail("table", f"x must increase (got {xs})")
        return self

    def below_table(self, pts):
        """Mask of the points (N, dim) at or below `table` (all of them without one)."""
        if self.table is None:
            return np.ones(len(pts), bool)
        xs, zs = np.asarray(self.table, float).T
        return pts[:, -1] <= np.interp(pts[:, 0], xs, zs) + 1e-9


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
    #: constant velocity only: the speed grows from 0 to `velocity` over this many seconds after `start`
    #: (and falls back to 0 over as many before `stop`) along a half cosine, so the acceleration stays
    #: at most pi |velocity| / (2 ramp) and the water the body pushes sees no pressure jump (a piston
    #: that raises a river without a water hammer); 0: the speed jumps
    ramp: NonNegFloat = 0.0

    @model_validator(mode="after")
    def _one_motion(self):
        """A constant velocity or an oscillation (amplitude and period), and stop after start (the
        number of components is checked against dim by Config)."""
        if (self.velocity is None) == (self.amplitude is None):
            fail("", "give either velocity or amplitude (with period)")
        if self.velocity is not None and self.period is not None:
            fail("period", "belongs to an oscillation (amplitude), not to a constant velocity")
        if self.amplitude is not None and self.period is None:
            fail("period", "is needed with amplitude")
        if self.stop is not None and self.stop <= self.start:
            fail("stop", f"must be later than start = {self.start}")
        if self.ramp > 0 and self.velocity is None:
            fail("ramp", "belongs to a constant velocity, not to an oscillation")
        if self.ramp > 0 and self.stop is not None and self.stop - self.start < 2 * self.ramp:
            fail("ramp", f"the speed must ramp up and down between start and stop: at most (stop - start) / 2 "
                 f"= {(self.stop - self.start) / 2:g}")
        return self


class Obstacle(Box):
    """A solid block of wall particles inside the tank (m)."""

    #: prescribed motion; default: fixed
    motion: Optional[ObstacleMotion] = None


def check_box(box: Box, dim: int, tank_size, key: str) -> None:
    """dim values per corner, inside the tank."""
    need_len(box.min, dim, f"{key}.min")
    need_len(box.max, dim, f"{key}.max")
    inside(box.min, box.max, tank_size, key)


def check_geometry(cfg) -> None:
    """Lists of dim values (tank, gravity, blocks, motions), water and obstacles inside the tank."""
    d = cfg.dim
    need_len(cfg.tank.size, d, "tank.size")
    if cfg.gravity is not None:
        need_len(cfg.gravity, d, "gravity")
    for group in ("water", "obstacles"):
        for k, box in enumerate(getattr(cfg, group)):
            check_box(box, d, cfg.tank.size, f"{group}[{k}]")
    for k, box in enumerate(cfg.obstacles):
        m = box.motion
        if m is not None:
            need_len(m.velocity if m.velocity is not None else m.amplitude, d,
                     f"obstacles[{k}].motion.{'velocity' if m.velocity is not None else 'amplitude'}")


def check_tank_room(cfg) -> None:
    """Every side of the tank holds 2 particles."""
    if min(cfg.tank.size) < 2 * cfg.dx:
        fail("tank.size", f"every side must hold at least 2 particles of dx = {cfg.dx}")


def periodic_cell(cfg) -> float:
    """Neighbour-search cell of the mode (m): the support radius 2.4 dx (isph), or 2 h_max plus the
    Verlet skin (wcsph_biot, h_max = 1.1 h0 with variable h)."""
    re = SUPPORT_FACTOR * cfg.dx
    if cfg.mode == "isph":
        return re
    h_hi = (1.1 if cfg.wcsph.variable_h else 1.0) * 0.5 * re
    return 2.0 * h_hi + cfg.wcsph.neighbour_skin * re


def check_periodic(cfg) -> None:
    """tank.periodic: valid distinct axes, each a whole number of dx long and at least 3 search cells;
    a Taylor-Green block needs a 2D doubly periodic tank."""
    per = cfg.tank.periodic
    if len(set(per)) != len(per):
        fail("tank.periodic", f"lists an axis twice: {per}")
    cell = periodic_cell(cfg)
    for a in per:
        if not 0 <= a < cfg.dim:
            fail("tank.periodic", f"axis {a} does not exist in {cfg.dim}D (axes 0 to {cfg.dim - 1})")
        L = cfg.tank.size[a]
        n = L / cfg.dx
        if abs(n - round(n)) > 1e-6 * max(1.0, n):
            fail("tank.size", f"the period along periodic axis {a}, {L:g} m, must be a whole number of "
                 f"dx = {cfg.dx:g} (it is {n:.6g})")
        if L < 3.0 * cell:
            fail("tank.size", f"the period along periodic axis {a}, {L:g} m, must hold 3 neighbour-search "
                 f"cells of {cell:.4g} m (at least {3.0 * cell:.4g} m)")
    for k, block in enumerate(cfg.water):
        if block.initial_velocity == "taylor_green" and (cfg.dim != 2 or sorted(per) != [0, 1]):
            fail(f"water[{k}].initial_velocity", "taylor_green needs dim 2 and tank.periodic [0, 1]")
