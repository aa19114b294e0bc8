"""What pore water's number density is measured against in mode isph, a mixin of ISPHSolver.

- A neighbour's share of i's number density (counts by filled volume, eps_i / eps_j for water);
- the rest density eps_i rho_w (eq 33's rho_bar) times the rest fill of water that starts in or next to
  ground (`_k_rest_fill`), the state eq 31's stabilisation relaxes towards;
- <rho_i> over the pore lattice's support (`_k_pore_density`, isph.ground_density_support pore /
  interior);
- drained pore water, a candidate of the cone test and of the tension rule (`_drained`).
docs/isph.md, "The stabilisation's rest state in the ground".
"""

import taichi as ti

from ..scene import WALL, WATER
from ..sph import kernels, operators


class GroundDensity:
    """Rest state and readings of the density of pore water (mixin of ISPHSolver: uses its fields and grid)."""

    @ti.kernel
    def _k_pore_density(self):
        """<rho_i> of pore water (eps_i < 1) over the pore lattice's support, r_e eps_i^(-1/dim) (at most
        2 r_e; isph.ground_density_support pore), for eq 31's stabilisation. On the pore lattice that
        support holds as many neighbours as r_e holds in free water, and the sum reads eps_i rho_w (the
        kernel widened by the lattice's own scale). Neighbours count as in _k_density (_density_share);
        the cells within the support are searched (the grid's cells are r_e wide). `pore_read` says where
        eq 31 takes this reading: everywhere in ground, or (interior) where every water particle within
        the support has the particle's own porosity, so that water on eq 32's ramp is read over r_e."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1 and self.eps[i] < 1.0:
                xi = self.x[i]
                hp = ti.min(ti.pow(self.eps[i], -1.0 / self.dim), 2.0) * self.h
                reach2 = 4.0 * hp * hp
                wsum = kernels.w(0.0, hp, self.dim)
                uniform = 1
                for off in ti.grouped(ti.ndrange(*([(-2, 3)] * self.dim))):
                    if self.grid.cell_gap2(xi, off) < reach2:
                        a, b = self.grid.cell_range(xi, off)
                        for j in range(a, b):
                            if j != i and self.active[j] != 0 and (self.kind[j] == WATER or self.kind[j] == WALL) \
                                    and self._present(j):
                                r = operators.rel(xi, self.x[j], self.period).norm()
                                if r < 2.0 * hp:
                                    wsum += self._density_share(i, j) * kernels.w(r, hp, self.dim)
                                    if ti.static(self.pore_interior):  # noqa: SIM102 (compiled only with it)
                                        if self.kind[j] == WATER and ti.abs(self.eps[j] - self.eps[i]) > 1e-6:
                                            uniform = 0
                self.rho_pore[i] = self.mass * wsum / self.kernel_sum
                self.pore_read[i] = uniform

    @ti.func
    def _density_share(self, i, j):
        """What neighbour j adds to particle i's number density, in units of i's own particle: a water
        particle its bulk volume m / (eps_j rho_w) over i's, eps_i / eps_j (a water particle in ground fills
        1 / eps_j lattice cells, so the count and the density near a soil surface measure how full the
        support is, not how many particles it holds; identical to counting particles where eps is
        uniform); a wall particle water of mass eps_i m at the wall lattice (volume dx^d), eps_i."""
        share = self.eps[i]
        if self.kind[j] == WATER:
            share = self.eps[i] / self.eps[j]
        return share

    @ti.func
    def _rest_density(self, i):
        """<rho_i> of water particle i at rest: eps_i rho_w, times its rest fill (_k_rest_fill) with porous
        ground. Eq 31's stabilisation relaxes towards it; the ground's free-surface and tension rules
        measure a drained pore against fractions of it."""
        out = self.eps[i] * self.rho_w
        if ti.static(self.porous):
            out *= self.rest_fill[i]
        return out

    @ti.func
    def _drained(self, i):
        """Pore water (eps_i < 1) that has let air into its pores: <rho_i> below isph.ground_tension_fill of
        its rest value. It is a candidate of the cone test (_k_surface_cone) and takes the tension rule
        (_k_tension)."""
        return self.eps[i] < 1.0 and self.rho_n[i] < self.tension_fill * self._rest_density(i)

    @ti.kernel
    def _k_rest_fill(self):
        """Rest density of water that starts in or next to ground: <rho_i> / rho_bar_i at t = 0.

        The kernel sum of a pore lattice is tabulated (K(eps)), but water placed in ground fills its
        block on a lattice rounded to the block, and across a soil surface two lattices meet: <rho> at
        rest differs from rho_bar there by a few per cent (measured: -6 % on the free-water side of a
        surface over eps 0.3, +2 to +5 % inside). The eq 31 stabilisation would read that as a density
        error; in free water particles move it away within steps, but in fine sand (D ~ 2000) the flow
        that corrects it is D times slower, so the stabilisation pressure stays and adds up over the
        ground's depth (+47 % at the bottom of 10 cm of sand). Taking the packing at t = 0 as the rest
        state for these particles (only they, and clamped to [0.8, 1.25]) keeps the stabilisation
        acting on compression and dilation since the start, as for free water."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1 and self.free[i] == 0:
                near = self.eps[i] < 1.0
                for k in range(self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    if self.kind[j] == WATER and self.eps[j] < 1.0:
                        near = True
                if near:
                    ratio = self.rho_n[i] / (self.eps[i] * self.rho_w)
                    self.rest_fill[i] = ti.min(ti.max(ratio, 0.8), 1.25)
                    if ti.static(self.pore_density):  # noqa: SIM102 (compiled only with the option)
                        if self.eps[i] < 1.0:
                            # over the block's packing: its rounding is water above or below the pores,
                            # which the stabilisation is to relax (42 particles for 40 in the 10 mm plug);
                            # water read over r_e at t = 0 (interior: on a ramp) fills its pores
                            fill = 1.0
                            if self.pore_read[i] == 1:
                                fill = self.rho_pore[i] / (self.eps[i] * self.rho_w * self.packing[i])
                            self.rest_fill_pore[i] = ti.min(ti.max(fill, 0.8), 1.25)
