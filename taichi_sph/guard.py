"""Stability guard shared by both solver modes: one place that decides when a run has gone wrong.

Causes and their families (exit codes in taichi_sph/errors.py):
- non-finite position, velocity, pressure or density (`nonfinite`, exit 4);
- speed above guard.max_speed, density ratio rho / rho_ref outside [guard.min_density_ratio,
  guard.max_density_ratio], a soil particle's pore pressure beyond guard.max_pore_pressure in magnitude,
  neighbour-list overflow (`bounds`, exit 3);
- pressure solver (CG) diverged or not converged, adaptive time step below timestep.min (`solver`, exit 5);
- particles leaving the domain when guard.out_of_domain is `error` (else removed, counted, warned),
  a wall particle that moved, water or air inside a wall when guard.wall_crossing is `error` (else
  counted and warned) (`domain`, exit 6).

Every message has the same shape: "step S, t = T s: <quantity> ... (particle ids ...)". The solvers call the
helpers of taichi_sph/instability.py (re-exported here) at the places they detect a cause inside a step
(cheap reductions already in their kernels); the driver calls StabilityGuard.after_step every step (speed) and StabilityGuard.check_fields
every guard.every steps and on every frame (the host-side checks: non-finite, density ratio, walls at
rest, fluid inside walls, pore pressure).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from .backend import ids_text
from .errors import InstabilityError
from .instability import (  # noqa: F401  (the solvers call them as guard.*)
    neighbour_overflow_error,
    non_finite_error,
    out_of_domain,
    solver_failure,
    time_step_error,
    where,
)
from .kinds import AIR, SOIL, WALL, WATER

log = logging.getLogger("taichi_sph")

#: guard.max_density_ratio when not given, per mode (see the key's documentation)
DEFAULT_MAX_DENSITY_RATIO = {"wcsph_biot": 1.3, "isph": 3.0}
#: a wall particle counts as moved beyond this fraction of dx (walls are never integrated: exact zero)
WALL_TOLERANCE = 1.0e-6
#: a water or air particle is inside a wall once its centre is past the wall's face (the tank interior's
#: side, an obstacle's box) by more than this fraction of dx: past the centres of the wall's first layer
#: (half a spacing behind the face). Deepest past a face over whole runs (frames): dam break isph
#: (configs/dambreak.yaml) 0.004 dx, dam break wcsph_biot at dx = a / 20 0.42 dx, breakwater 0
WALL_CROSSING_DEPTH = 0.5
#: gauge pressure of vacuum (Pa; pressures are gauge, 0 at a free surface): no liquid is held in tension
#: below it, water cavitates first. Mode isph's pressure equation can ask for more where a surface it
#: did not find reads as dilated water (docs/freefall.md, "Small fixed steps"); the guard warns
VACUUM_GAUGE_PRESSURE = -101325.0


class StabilityGuard:
    """Host-side checks the driver makes; built once per run from the config and the scene's kinds."""

    def __init__(self, cfg, kind: np.ndarray, rho_ref: np.ndarray, speed_bound: float, body=None, motions=(),
                 pore_pressure_bound: float | None = None):
        g = cfg.guard
        self.every = g.every
        self.speed_bound = float(speed_bound)
        self.pore_bound = pore_pressure_bound
        #: the largest pore-pressure magnitude of a soil particle at any full check (Pa)
        self.pore_max = 0.0
        self.max_ratio = g.max_density_ratio or DEFAULT_MAX_DENSITY_RATIO[cfg.mode]
        self.min_ratio = g.min_density_ratio
        self.kind = np.asarray(kind)
        self.rho_ref = np.asarray(rho_ref, dtype=float)
        # density ratio of water and air only (soil has its own density and no such bound here)
        self.fluid = np.isin(self.kind, (WATER, AIR))
        #: the lowest water pressure of any step (mode isph's pressure_min), when, and the steps below vacuum
        self.pressure_min = math.inf
        self.pressure_min_time = 0.0
        self.below_vacuum = 0
        # soil particles with a pore pressure (mode wcsph_biot; mode isph's soil markers carry none)
        self.soil = (self.kind == SOIL) & (cfg.mode == "wcsph_biot")
        self.wall = self.kind == WALL
        self.wall_tol = WALL_TOLERANCE * cfg.dx
        self.wall0 = None
        # obstacles with a prescribed motion (sph/wall_motion.py): index of each wall particle's motion
        self.motions = list(motions)
        self.periodic, self.tank_size = [], []
        if self.motions:  # a moving wall wraps across periodic sides like the fluid
            self.periodic = [ax for ax in cfg.tank.periodic if ax < cfg.dim]
            self.tank_size = list(cfg.tank.size)
        self.wall_body = np.asarray(body)[self.wall] if body is not None else np.full(int(self.wall.sum()), -1)
        self.walls = WallFaces(cfg, self.motions)
        self.crossing_action = g.wall_crossing
        #: water or air particles inside a wall at the last check, and the most at any check of this process
        self.crossed = 0
        self.crossed_max = 0

    def _wall_displacement(self, time: float) -> np.ndarray:
        """Where the motions have moved each wall particle by `time` (zero for fixed walls)."""
        out = np.zeros((len(self.wall_body), self.pos_dim))
        for b, m in enumerate(self.motions):
            out[self.wall_body == b] = m.displacement(time)
        return out

    def start(self, fields: dict, time: float = 0.0) -> None:
        """Remember where the walls were at t = 0 (a resumed run: where they are less their motion)."""
        pos = np.asarray(fields["position"], dtype=float)
        self.pos_dim = pos.shape[1]
        self.wall0 = np.array(pos[self.wall], dtype=float)
        if self.motions:
            self.wall0 -= self._wall_displacement(time)

    def due(self, step: int) -> bool:
        return step % self.every == 0

    def after_step(self, step: int, time: float, diag: dict, fastest, pressures=None) -> None:
        """Per-step check from the solver's reductions: the speed bound (`fastest()` gives the particle id);
        where the solver reports its lowest water pressure (mode isph), water below vacuum: a warning at the
        first such step, naming the particle (`pressures()` gives every particle's, in id order), and a count
        (`report_tension`)."""
        speed = diag["max_speed"]
        if not speed <= self.speed_bound:  # NaN fails too
            pid = fastest()
            raise InstabilityError(
                f"{where(step, time)}: speed {speed:.4g} m/s exceeds the bound {self.speed_bound:.4g} m/s "
                f"(guard.max_speed) at particle id {pid}", step=step, time=time, quantity="speed", particles=[pid],
                family="bounds" if math.isfinite(speed) else "nonfinite")
        p = diag.get("pressure_min")
        if p is None:
            return
        if p < self.pressure_min:
            self.pressure_min, self.pressure_min_time = p, time
        if p < VACUUM_GAUGE_PRESSURE:
            self.below_vacuum += 1
            if self.below_vacuum == 1:
                log.warning("%s: water pressure %.4g kPa at particle id %s, below vacuum (%.4g kPa gauge): the "
                            "pressure equation pulls on the water harder than a liquid holds; at smaller fixed steps "
                            "in porous ground this has thrown water through it (docs/freefall.md, \"Small fixed "
                            "steps\")", where(step, time), p / 1e3, self._lowest_water(pressures),
                            VACUUM_GAUGE_PRESSURE / 1e3)

    def _lowest_water(self, pressures):
        """Id of the water particle with the lowest pressure ("?" without the pressures)."""
        if pressures is None:
            return "?"
        p = np.where(self.kind == WATER, np.asarray(pressures(), dtype=float), np.inf)
        return int(np.argmin(np.where(np.isnan(p), np.inf, p)))

    def tension_state(self) -> list:
        """The lowest pressure, when, and the steps below vacuum so far, for a checkpoint."""
        return [self.pressure_min, self.pressure_min_time, self.below_vacuum]

    def restore_tension(self, state) -> None:
        """Go on from a checkpoint's `tension_state()`."""
        pmin, tmin, below = state
        self.pressure_min, self.pressure_min_time, self.below_vacuum = float(pmin), float(tmin), int(below)

    def report_tension(self, writer, summary: dict) -> None:
        """Root attributes `pressure_min`, `pressure_min_time`, `below_vacuum_steps`, and a warning that
        sums the run up when any step held water below vacuum (mode isph; nothing for a solver without
        pressure_min)."""
        if not math.isfinite(self.pressure_min):
            return
        summary.update(pressure_min=self.pressure_min, below_vacuum_steps=self.below_vacuum)
        writer.set_attrs(pressure_min=self.pressure_min, pressure_min_time=self.pressure_min_time,
                         below_vacuum_steps=self.below_vacuum)
        if self.below_vacuum:
            log.warning("water was held below vacuum in %d steps, lowest %.4g kPa (t = %.4g s): the results "
                        "may depend on dt", self.below_vacuum, self.pressure_min / 1e3, self.pressure_min_time)

    def check_fields(self, step: int, time: float, fields: dict) -> None:
        """Non-finite state, density ratio of fluid particles, pore pressure of soil particles, walls at rest,
        fluid inside walls (fields in id order: a frame's, or the solver's guard_fields, whose `finite` says
        per particle whether its position, velocity, pressure and density are finite)."""
        active = np.asarray(fields["active"], dtype=bool)
        if "finite" in fields:
            bad = ~np.asarray(fields["finite"], dtype=bool)
        else:
            bad = np.zeros(len(active), dtype=bool)
            for name in ("position", "velocity", "pressure", "density"):
                a = np.asarray(fields[name], dtype=float)
                bad |= ~np.isfinite(a.reshape(len(a), -1)).all(axis=1)
        bad &= active
        if bad.any():
            ids = np.flatnonzero(bad)
            raise InstabilityError(
                f"{where(step, time)}: non-finite position, velocity, pressure or density at {len(ids)} particle(s) "
                f"(particle ids {ids_text(ids)})", step=step, time=time, quantity="non-finite state",
                particles=ids, family="nonfinite")
        ratio = np.asarray(fields["density"], dtype=float) / self.rho_ref
        check = active & self.fluid
        for bound, over, name in ((self.max_ratio, ratio > (self.max_ratio or np.inf), "max_density_ratio"),
                                  (self.min_ratio, ratio < (self.min_ratio or -np.inf), "min_density_ratio")):
            hit = over & check
            if bound is not None and hit.any():
                ids = np.flatnonzero(hit)
                worst = ids[np.argmax(np.abs(ratio[ids] - 1.0))]
                raise InstabilityError(
                    f"{where(step, time)}: density ratio {ratio[worst]:.4g} beyond the bound {bound:g} "
                    f"(guard.{name}) at {len(ids)} particle(s) (particle ids {ids_text(ids)})", step=step,
                    time=time, quantity="density ratio", particles=ids, family="bounds")
        self.check_pore_pressure(step, time, fields, active)
        if self.wall0 is not None and len(self.wall0):
            expected = self.wall0 + self._wall_displacement(time) if self.motions else self.wall0
            off = np.asarray(fields["position"])[self.wall] - expected
            for ax in self.periodic:  # a moving wall wraps like the fluid
                L = float(self.tank_size[ax])
                off[:, ax] -= L * np.round(off[:, ax] / L)
            moved = np.abs(off).max(axis=1) > self.wall_tol
            if moved.any():
                ids = np.flatnonzero(self.wall)[moved]
                raise InstabilityError(
                    f"{where(step, time)}: {len(ids)} wall particle(s) moved (particle ids {ids_text(ids)})"
                    + (" off their prescribed motion" if self.motions else ""),
                    step=step, time=time, quantity="wall position", particles=ids, family="domain")
        self.check_wall_crossing(step, time, fields)

    def check_pore_pressure(self, step: int, time: float, fields: dict, active: np.ndarray) -> None:
        """Stop when a soil particle's pore pressure (its `pressure`, mode wcsph_biot) exceeds the bound in
        magnitude. Where soil raises the water's sound speed (~350 m/s at a levee), a pressure wave growing
        in the pore water changes its density by less than 1e-3 and moves it at under 1 m/s: neither the
        density ratio nor the speed bound sees it, while its pressure reaches tens of times the weight of
        the soil above it, which a pore pressure at rest cannot exceed."""
        check = active & self.soil
        if "pressure" not in fields or not check.any():
            return
        p = np.asarray(fields["pressure"], dtype=float)
        mag = np.abs(p)
        self.pore_max = max(self.pore_max, float(mag[check].max()))
        if self.pore_bound is None:
            return
        hit = check & (mag > self.pore_bound)
        if hit.any():
            ids = np.flatnonzero(hit)
            worst = ids[np.argmax(mag[ids])]
            raise InstabilityError(
                f"{where(step, time)}: pore pressure {p[worst]:.4g} Pa beyond the bound {self.pore_bound:.4g} Pa "
                f"(guard.max_pore_pressure) at {len(ids)} soil particle(s) (particle ids {ids_text(ids)})",
                step=step, time=time, quantity="pore pressure", particles=ids, family="bounds")

    def check_wall_crossing(self, step: int, time: float, fields: dict) -> None:
        """Count the active water and air particles inside a wall (WallFaces.depth > WALL_CROSSING_DEPTH dx):
        stop the run when guard.wall_crossing is `error`, else warn whenever the count changes."""
        check = np.asarray(fields["active"], dtype=bool) & self.fluid
        depth = np.zeros(len(check))
        if check.any():
            depth[check] = self.walls.depth(np.asarray(fields["position"], dtype=float)[check], time)
        inside = check & (depth > WALL_CROSSING_DEPTH * self.walls.dx)
        count = int(inside.sum())
        changed, self.crossed = count != self.crossed, count
        self.crossed_max = max(self.crossed_max, count)
        if not count:
            return
        ids = np.flatnonzero(inside)
        msg = (f"{where(step, time)}: {count} water or air particle(s) inside a wall, up to "
               f"{depth[ids].max() / self.walls.dx:.3g} dx past its face (particle ids {ids_text(ids)})")
        if self.crossing_action == "error":
            raise InstabilityError(msg + " (guard.wall_crossing: error)", step=step, time=time,
                                   quantity="wall crossing", particles=ids, family="domain")
        if changed:
            log.warning("%s", msg)


class WallFaces:
    """Where the walls of a config are: the tank's sides around its interior [0, size] (none across a
    periodic axis, none on top of an open tank) and the obstacles' boxes, each moved by its prescribed
    motion (the motions in the scene's order: the obstacles with a `motion`, in config order)."""

    def __init__(self, cfg, motions=()):
        self.dx = float(cfg.dx)
        self.size = np.asarray(cfg.tank.size, dtype=float)
        dim = len(self.size)
        self.periodic = [ax for ax in cfg.tank.periodic if ax < dim]
        #: (axis, has a wall below, has a wall above) for the axes that are not periodic
        self.sides = [(ax, True, not (ax == dim - 1 and cfg.tank.open_top)) for ax in range(dim)
                      if ax not in self.periodic]
        self.motions = list(motions)
        self.boxes = []  # (min, max, index into motions or -1)
        moving = 0
        for box in getattr(cfg, "obstacles", []):
            body = -1
            if box.motion is not None:
                body, moving = moving, moving + 1
            self.boxes.append((np.asarray(box.min, dtype=float), np.asarray(box.max, dtype=float), body))

    def depth(self, pos: np.ndarray, time: float) -> np.ndarray:
        """How far past a wall face each point is (m; 0 where it is in the open): beyond a side of the tank,
        or inside an obstacle's box by its distance to the nearest face."""
        out = np.zeros(len(pos))
        for ax, below, above in self.sides:
            if below:
                out = np.maximum(out, -pos[:, ax])
            if above:
                out = np.maximum(out, pos[:, ax] - self.size[ax])
        for lo, hi, body in self.boxes:
            if body >= 0:
                shift = np.asarray(self.motions[body].displacement(time), dtype=float)
                lo, hi = lo + shift, hi + shift
            inner = np.full(len(pos), np.inf)  # distance to the nearest face, where inside
            for ax in range(len(lo)):
                width = hi[ax] - lo[ax]
                u = pos[:, ax] - lo[ax]
                if ax in self.periodic:
                    L = float(self.size[ax])
                    if width >= L * (1 - 1e-9):  # the box spans the period: no face along this axis
                        continue
                    u = np.mod(u, L)
                inner = np.minimum(inner, np.where((u > 0) & (u < width), np.minimum(u, width - u), -np.inf))
            out = np.maximum(out, np.where(np.isfinite(inner) & (inner > 0), inner, 0.0))
        return out


def flag_field(n: int, ids=()) -> np.ndarray:
    """The frame field `flag`: 1 at the particles (ids) that stopped the run, else 0."""
    flag = np.zeros(n, dtype=np.int8)
    ids = [int(i) for i in ids if 0 <= int(i) < n]
    flag[ids] = 1
    return flag
