"""Free-surface tests of mode isph beyond eq 34's count (seed 000 section 3), a mixin of ISPHSolver.

Eq 34 flags particle i free surface when its neighbour count N_i falls below eps_i N_surf (in
`ISPHSolver._k_density`, with the threshold scaled to the pore lattice in the ground). Two tests here
complete it:
- closed bodies: every body of water (particles joined by pairs within `_body_reach`) gets a Dirichlet
  row, so that a drop or a cluster of pore water has a reference pressure (`_closed_bodies`);
- the cone test in and next to porous ground: a candidate is free surface only where a cone of its
  support, pointing away from its water, holds no water (`_k_surface_cone`; docs/isph.md, "Surface test
  in the ground"), and the flags it leaves for the next step (`_k_remember_air`).
"""

import taichi as ti

from ..scene import WATER
from ..sph import kernels, operators

#: sweeps of the lowest index through the water pairs per step (_closed_bodies): a body up to this many
#: pair hops across is found whole (a pair hop is up to BODY_LINK r_e)
BODY_SWEEPS = 6
#: two water particles belong to one body (_closed_bodies) when closer than this fraction of r_e. Beyond
#: it the pair's PPE coefficient (-dW/dr r / (r^2 + eta^2)) is below 2.2 % of its value at r = h: a cluster
#: of pore water joined to the rest only by such pairs has a PPE block of its own in all but name, with
#: no reference pressure. In the porous dam break at dx 5 mm such clusters of 2-4 particles in the dam,
#: joined by one pair at 0.97-0.98 r_e (a coefficient 1e-3 of the block's), were solved to 1e6-3e8 Pa
#: and thrown at 100-180 m/s (docs/isph.md, "Porous dam break")
BODY_LINK = 0.9
#: ... unless the pore lattice is sparser: neighbours on a pore lattice of spacing dx eps^(-1/dim) always
#: join (the pairs within LATTICE_LINK spacings), or ground of eps below (LATTICE_LINK / (BODY_LINK 2.4))^dim
#: would break into one-particle bodies, all made free surface
LATTICE_LINK = 1.05


class SurfaceTests:
    """Closed bodies and the cone test (mixin of ISPHSolver: uses its fields, grid and settings)."""

    def _closed_bodies(self):
        """Every body of water gets a Dirichlet row. A body (water particles joined by pairs within the
        support) that holds no free-surface particle while the rest of the water has some, a cluster of
        a few particles in the pores or the air that eq 34 and the cone test read as interior, has a PPE
        block with no reference pressure: CG does not converge on it (relative residual 32 after 2000
        iterations for a 2 x 2 drop in the air). A body of fewer particles than eq 34's free-water
        threshold N_surf (17 in 2D, 48 in 3D) cannot hold a particle with a full support of water, so
        all of it is free surface (a drop); a larger one gets one Dirichlet row, on its particle with the
        fewest water neighbours, which fixes its pressure level and keeps it incompressible. Bodies are
        found by propagating the lowest index through the water pairs, BODY_SWEEPS times; a body not
        settled by then (wider than that many pair hops) is left as it is: it is large, and a large body
        has a surface the tests find. The pair test (`_water_pair`) is taken once per step into
        `body_link`, and the sweeps stop at the first that changes no label (the labels are then final):
        the same labels as six full sweeps, at a third of the cost (coarse free fall, 2 threads: 2.3
        against 6.9 ms of a 28-41 ms step). Only with porous ground
        (`soil`): in free water eq 34's count finds every drop (a body of fewer than N_surf particles has
        no particle with N_surf neighbours)."""
        self._k_body_init()
        for _ in range(BODY_SWEEPS):
            self.body_changed[None] = 0
            self._k_body_sweep()
            if self.body_changed[None] == 0:
                break
        self._k_body_close()

    @ti.func
    def _body_reach(self, eps):
        """The pair test's distance at porosity eps: BODY_LINK r_e, or LATTICE_LINK pore-lattice spacings
        dx eps^(-1/dim) where that is farther (ground of eps below ~0.24 in 2D, ~0.11 in 3D, whose lattice
        neighbours lie beyond BODY_LINK r_e), never beyond r_e. It does not grow with eps."""
        return ti.min(ti.max(BODY_LINK * self.re, LATTICE_LINK * self.dx * ti.pow(eps, -1.0 / self.dim)), self.re)

    @ti.func
    def _water_pair(self, i, j) -> ti.i32:
        """Whether i and j are water of one body: both solved and closer than the reach (_body_reach) of
        the sparser of the two, the larger of their two reaches (body_reach, taken per particle: a power
        per pair cost as much as the rest of the body search)."""
        ok = 0
        if self.kind[j] == WATER and self.solve_mask[j] == 1 and j != i:
            link = ti.max(self.body_reach[i], self.body_reach[j])
            if operators.rel(self.x[i], self.x[j], self.period).norm() < link:
                ok = 1
        return ok

    @ti.kernel
    def _k_body_init(self):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.body[i] = i
            self.body_free[i] = 0
            self.body_open[i] = 0
            self.body_pick[i] = ti.i64(1) << 62
            self.body_size[i] = 0
            if self.solve_mask[i] == 1:
                self.body_reach[i] = self._body_reach(self.eps[i])
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                for k in range(self.grid.nbr_count[i]):
                    self.body_link[i, k] = ti.cast(self._water_pair(i, self.grid.nbr[i, k]), ti.i8)

    @ti.kernel
    def _k_body_sweep(self):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                lowest = self.body[i]
                for k in range(self.grid.nbr_count[i]):
                    if self.body_link[i, k] == 1:
                        lowest = ti.min(lowest, self.body[self.grid.nbr[i, k]])
                if ti.atomic_min(self.body[i], lowest) > lowest:
                    self.body_changed[None] = 1

    @ti.kernel
    def _k_body_close(self):
        self.closed_bodies[None] = 0
        self.any_free[None] = 0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                b = self.body[i]
                if self.free[i] == 1:
                    self.body_free[b] = 1
                    self.any_free[None] = 1
                count = 0
                for k in range(self.grid.nbr_count[i]):
                    if self.body_link[i, k] == 1:
                        count += 1
                        if self.body[self.grid.nbr[i, k]] != b:
                            self.body_open[b] = 1
                ti.atomic_min(self.body_pick[b], ti.i64(count) * ti.i64(self.n) + ti.i64(i))
                ti.atomic_add(self.body_size[b], 1)
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1 and self.any_free[None] == 1:
                b = self.body[i]
                if self.body_free[b] == 0 and self.body_open[b] == 0:
                    pick = self.body_pick[b] % ti.i64(self.n) == ti.i64(i)
                    if pick or self.body_size[b] < self.n_surf:
                        self.free[i] = 1
                    if pick:
                        ti.atomic_add(self.closed_bodies[None], 1)

    @ti.kernel
    def _k_surface_cone(self):
        """Free surface in and next to porous ground: eq 34's candidates confirmed by an empty cone.

        A water particle in the ground (eps_i < 1), with a neighbour there, or within the markers' reach
        (the outer half of a face's ramp, where eq 32 still gives eps 1 but the pore water below is
        sparse) is a candidate when eq 34's count marked it free, or (in free water) when the plain count
        of its neighbours is below N_surf: below a plug's exit face the filled-volume count reads the pore
        water as full, so water hanging there was never free and sucked on the plug. In the ground it is a
        candidate too where it has drained, <rho_i> below isph.ground_tension_fill of its rest value
        (isph.ground_drained_candidate): a front entering dry ground as a sheet at the free water's spacing
        passes the count, and held as an interior row its deficit was pulled on by eq 31's term (docs/isph.md,
        "Drained pore water a candidate of the cone"). A candidate is free
        surface only if no neighbour (water, or a wet wall) lies within the cone of half-angle
        `isph.ground_surface_cone` about its outward normal n_i = -sum_j V_j grad W_ij (V_j the bulk
        volume m / (eps_j rho_w), dx^d for a wall): the scan-region test of Marrone et al. (2010, J.
        Comput. Phys. 229), with the support as its reach.
        On a surface the half-space beyond it is empty whatever the arrangement; inside the ground a
        disordered pore lattice lowers the count (6-8 neighbours within r_e in 2D at eps 0.4) but leaves
        no empty cone, so it is not flagged (docs/isph.md, "Surface test in the ground"). An empty cone
        counts only where air can reach it: the particle or a water neighbour was free surface at the end
        of the last step, or the cone is empty out to 2 r_e (_cone_empty_beyond). A gap of a pore spacing
        inside saturated ground, which the flow opens and closes from step to step, holds no air and is
        not a surface: flagged, each such row was a sink for a step, and the flow into it was projected
        out in one step when it closed (pressure spikes of 10-20 kPa in the permeameter's plug at dt
        0.25 ms). A candidate with at most dim water neighbours is free whatever its cone: a drop of a few
        particles hanging in a corner of walls, which block its cone, would otherwise have no Dirichlet row
        (a singular block of the PPE, on which CG diverged)."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1 and self.isolated[i] == 0:
                xi = self.x[i]
                near = self.eps[i] < 1.0 or self.ground_reach[i] == 1
                plain = 0.0
                n_water = 0
                gsum = ti.Vector.zero(float, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if not self._present(j):
                        continue
                    if self.kind[j] == WATER:
                        n_water += 1
                        if self.eps[j] < 1.0:
                            near = True
                    plain += 1.0
                    if r > 0.0:
                        gsum += self._volume(j) * kernels.grad_w(rij, r, self.h, self.dim)
                self.candidate[i] = 0
                if near:
                    candidate = self.free[i] == 1
                    if self.eps[i] >= 1.0 and plain < self.n_surf:
                        candidate = True
                    if ti.static(self.drained_candidate):  # noqa: SIM102 (compile-time if)
                        if self._drained(i):
                            candidate = True
                    if candidate:
                        self.candidate[i] = 1
                    is_free = 0
                    gn = gsum.norm()
                    # a drop of a few particles hanging in a corner of walls, which block its cone: at most dim
                    # water neighbours, in units of the pore lattice's count N(eps) / N(1) (a saturated corner
                    # of eps 0.3 ground in 2D has 2 water neighbours, as its lattice holds 4 in the bulk)
                    few = self.dim * 1.0
                    if ti.static(self.n_surf > 0):
                        if self.eps[i] < 1.0:
                            few = self.dim * self._table_at(self.nsurf_tab, self.eps[i]) / self.n_surf
                    if candidate and gn > 0.0:
                        is_free = 1
                        if n_water > few:
                            n_out = -gsum / gn
                            for k in range(self.grid.nbr_count[i]):
                                j, rij, r = self._pair(i, k, xi)
                                if self._present(j):
                                    if self._in_cone(rij, r, n_out):
                                        is_free = 0
                            # air reaches an empty cone only from the air: from a surface there in the
                            # last step (its own or a water neighbour's), or through a cone empty to 2 r_e
                            if is_free == 1 and self.air_last[i] == 0:
                                path = 0
                                for k in range(self.grid.nbr_count[i]):
                                    j = self.grid.nbr[i, k]
                                    if self.kind[j] == WATER and self.air_last[j] == 1:
                                        path = 1
                                if path == 0:
                                    path = self._cone_empty_beyond(i, xi, n_out)
                                is_free = path
                    # draining ground: scattered pore water with air between, a deficit of number
                    # density with no empty cone (isph.ground_surface_density)
                    if ti.static(self.ground_beta > 0.0):
                        if self.rho_n[i] < self.ground_beta * self._rest_density(i):
                            is_free = 1
                    self.free[i] = is_free

    @ti.func
    def _in_cone(self, rij, r, n_out) -> ti.i32:
        """Whether the neighbour at x_i - rij (distance r) lies in particle i's cone of half-angle
        `isph.ground_surface_cone` about its outward normal n_out."""
        return -rij.dot(n_out) >= self.cone_cos * r

    @ti.func
    def _cone_empty_beyond(self, i, xi, n_out) -> ti.i32:
        """1 if no water particle (or wet wall) lies in particle i's cone about n_out out to twice the
        support, where a surface (dry ground ahead of a front, the open space below a plug) has air and a
        gap between pore particles has water beyond it: the grid's cells around x_i + 1.5 r_e n_out are
        searched (the cone's part beyond that block, wide of its axis, is not)."""
        q = xi + 1.5 * self.re * n_out
        empty = 1
        # a loop, not unrolled: unrolled over the 27 cells of 3D it doubled the compilation of the
        # cone kernel's step (8 -> 18 s for the coarse free fall)
        for off in ti.grouped(ti.ndrange(*([(-1, 2)] * self.dim))):
            a, b = self.grid.cell_range(q, off)
            for k in range(a, b):
                if k != i and self.active[k] != 0 and self._present(k):
                    rik = operators.rel(xi, self.x[k], self.period)
                    r = rik.norm()
                    if r < 2.0 * self.re and self._in_cone(rik, r, n_out):
                        empty = 0
        return empty

    @ti.kernel
    def _k_remember_air(self):
        """The step's free-surface flags, where the next step's cone test looks for air (air_last)."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.air_last[i] = self.free[i]
