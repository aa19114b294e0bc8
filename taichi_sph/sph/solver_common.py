"""What the solvers of both modes share outside their kernels: phase timers and the start of a neighbour
search (cell sort, removal of particles that left the domain, reordering of every particle array)."""

import math
import time as _time
from types import MappingProxyType

import numpy as np
import taichi as ti

from ..instability import out_of_domain
from ..kinds import WALL


class SolverCommon:
    """Mixin of ISPHSolver and WCSPHSolver. Expects `cfg`, `grid` (sph.grid.NeighbourGrid), `x`, `active`,
    `ids`, `n`, `serial` (the loops run serially: a small scene on the CPU), `g_abs`, `particle_fields`
    (every per-particle field, reordered together), `timers` (dict of seconds per phase), `removed_total`,
    `step_count` and `time`. Gives the defaults of the solver contract (contract.Solver) that a mode may
    override."""

    #: extra run-file attributes (none by default)
    run_attrs = MappingProxyType({})
    #: air's reference density; None: the mode has no air
    rho_a = None
    #: the driver's TimeStepper chooses the step unless a solver proposes its own (`propose_dt`)
    proposes_dt = False

    def propose_dt(self) -> tuple[float, int]:
        """Only solvers with `proposes_dt` choose their own time step."""
        raise NotImplementedError(f"{type(self).__name__} does not choose its time step (proposes_dt is False)")

    def _id_order(self) -> np.ndarray:
        """order[id] = the index particle id holds now (the neighbour search reorders the arrays)."""
        n = self.n
        order = np.empty(n, dtype=np.int64)
        order[self.ids.to_numpy()[:n]] = np.arange(n)
        return order

    #: the per-particle density field that guard_fields reports
    density_field = "rho"

    def guard_fields(self) -> dict:
        """What the guard's full check reads (guard.check_fields) every `guard.every` steps, in id order:
        position, density (the water's at wall particles, as fields_by_id reports), pressure, active, and
        `finite`: whether position, velocity, pressure and density are all finite (all the check asks of
        velocity). One kernel packs them by particle id into one array, read in one transfer: at the
        20k dam break (wcsph) the check every tenth step cost 0.32 ms a step, 11 % of the run, when each
        field was read and put in id order on the host."""
        n, dim = self.n, self.dim
        if getattr(self, "_guard_out", None) is None:
            self._guard_out = np.empty((n, dim + 4), dtype=np.float64)
        out = self._guard_out
        self._k_guard_pack(out, getattr(self, self.density_field))
        return {"position": out[:, :dim].copy(), "density": out[:, dim].copy(), "finite": out[:, dim + 1] > 0.5,
                "active": out[:, dim + 2] > 0.5, "pressure": out[:, dim + 3].copy()}

    @ti.kernel
    def _k_guard_pack(self, out: ti.types.ndarray(dtype=ti.f64, ndim=2), rho: ti.template()):
        """Row ids[i] of `out`: x_i, the density the guard checks (rho_w at wall particles), 1 where x, v, p
        and rho are all finite, active, p_i."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            k = self.ids[i]
            for d in ti.static(range(self.dim)):
                out[k, d] = ti.cast(self.x[i][d], ti.f64)
            r = ti.cast(self.rho_w, ti.f64) if self.kind[i] == WALL else ti.cast(rho[i], ti.f64)
            out[k, ti.static(self.dim)] = r
            # one sum is non-finite when any of its terms is (as the per-step diagnostics test it)
            val = ti.cast(self.x[i].sum() + self.v[i].sum() + self.p[i], ti.f64) + r
            out[k, ti.static(self.dim + 1)] = 0.0 if (ti.math.isnan(val) or ti.math.isinf(val)) else 1.0
            out[k, ti.static(self.dim + 2)] = ti.cast(self.active[i] != 0, ti.f64)
            out[k, ti.static(self.dim + 3)] = ti.cast(self.p[i], ti.f64)

    def max_speed_bound(self) -> float:
        """Speed above which the guard stops the run: `guard.max_speed`, or 20 sqrt(g H) with H the tank's
        height (a free fall from the top of the tank reaches sqrt(2 g H))."""
        if self.cfg.guard.max_speed is not None:
            return self.cfg.guard.max_speed
        height = float(self.cfg.tank.size[-1])
        return 20.0 * math.sqrt(self.g_abs * height) if self.g_abs > 0 else 100.0

    def max_pore_pressure_bound(self) -> float | None:
        """No pore pressure on soil particles by default (mode wcsph_biot overrides it)."""
        return None

    def _tick(self, key: str, t0: float) -> float:
        """Add the time since t0 to phase `key`; return now (the start of the next phase)."""
        t1 = _time.perf_counter()
        self.timers[key] += t1 - t0
        return t1

    def _sort_and_reorder(self, reorder: bool = True) -> None:
        """Counting sort into the cells; particles outside the grid are taken out, counted, and reported
        to instability.out_of_domain (which stops the run or warns, per `guard.out_of_domain`); then every
        particle array is put in cell order (memory locality of the neighbour loops), unless `reorder` is
        False."""
        removed = self.grid.sort(self.x, self.active, self.n)
        if len(removed):
            ids = self.ids.to_numpy()[removed]
            self.removed_total += len(removed)
            out_of_domain(self.cfg, self.step_count, self.time, ids, self.removed_total)
        if not reorder:
            return
        for f in self.particle_fields:
            self.grid.reorder(f, self.n)
