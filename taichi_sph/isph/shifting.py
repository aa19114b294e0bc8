"""Particle shifting of mode isph, a mixin of ISPHSolver (not in the seed; docs/isph.md).

dr = -A h |u| dt grad C (Lind et al. 2012; A isph.shifting, isph.ground_shifting for pore water), grad C =
sum_j V_j (1 + 0.2 (W_ij / W_ref)^4) grad W_ij with its anti-pairing term, the component along the surface
normal removed within the support of a free surface, capped at isph.shifting_max. In porous ground W_ref is
taken at the pore lattice's spacing, and for wall pairs at pore water's rest distance from the wall; where
the shift's diffusion number A |u| dt / h over the water in the ground exceeds SHIFT_NUMBER_MAX, the step's
shift is taken in substeps (docs/isph.md, "Shifting in substeps").
"""

import taichi as ti

from ..scene import WALL, WATER
from ..sph import kernels, operators

#: the shifting is an explicit diffusion of the particles' concentration with coefficient A h |u|; where its
#: number A |u| dt / h over the water in the ground exceeds this, the step's shift is taken in substeps,
#: each with grad C at the positions the one before left (at most SHIFT_SUBSTEPS_MAX; docs/isph.md,
#: "Shifting in substeps")
SHIFT_NUMBER_MAX = 0.25
SHIFT_SUBSTEPS_MAX = 4


class Shifting:
    """The shift and its grad C (mixin of ISPHSolver: uses its fields, grid and settings)."""

    @ti.func
    def _anti_pairing_reference(self, i):
        """The kernel at the spacing of water at i's porosity, W(dx / eps^(1/dim)) (the lattice spacing in
        free water), against which the shift's anti-pairing term measures i's water pairs (`_grad_c_pair`)."""
        w_ref = self.w_dx
        if ti.static(self.porous and self.shifting):  # noqa: SIM102 (compile-time if)
            if self.eps[i] < 1.0:
                w_ref = kernels.w(self.dx * self.eps[i] ** (-1.0 / self.dim), self.h, self.dim)
        return w_ref

    @ti.func
    def _wall_anti_pairing_reference(self, i):
        """The kernel at the distance at which i rests from the first layer of a wall, against which the
        shift's anti-pairing term measures i's wall pairs (`_grad_c_pair`): W(dx) in free water; water at
        porosity eps rests at half its lattice spacing s = dx / eps^(1/dim) from the wall's face, so at
        (dx + s) / 2 from the first wall layer (dx / 2 behind the face): 1.29 dx at eps 0.4 in 2D."""
        w_wall = self.w_dx
        if ti.static(self.porous and self.shifting):  # noqa: SIM102 (compile-time if)
            if self.eps[i] < 1.0:
                w_wall = kernels.w(0.5 * self.dx * (1.0 + self.eps[i] ** (-1.0 / self.dim)), self.h, self.dim)
        return w_wall

    @ti.func
    def _grad_c_pair(self, j, vj, r, gw, w_ref, w_wall):
        """A pair's term of the shift's grad C: V_j (1 + 0.2 (W_ij / W_ref)^4) grad W_ij (Lind et al. 2012's
        anti-pairing term), W_ref = w_ref for a water neighbour j (`_anti_pairing_reference`), w_wall for a
        wall particle (`_wall_anti_pairing_reference`; the same W(dx) in free water).

        Measured against the pore lattice's W(s), as wall pairs of pore water were before, a wall pair at
        eps 0.4 in 2D carried 8.7 times its V_j grad W at the rest distance (120 times at dx; against
        W((dx + s) / 2) 1.2 times, as every pair at its rest distance in free water), and the shift pushed
        the pore water off the walls wherever it flowed. In the Darcy slab (configs/darcy_column.yaml, slip
        walls) the columns beside the walls moved in by 0.9 mm in 60 ms and compressed the water between
        them, and eq 31 answered with up to +28.7 / +57 Pa over the surface value at dt 1 / 0.5 ms, where
        a slab draining under gravity alone has none (+9.9 / +17 Pa since; docs/isph.md, "The shift's
        anti-pairing at walls in the ground")."""
        ref = w_ref
        if ti.static(self.porous):  # noqa: SIM102 (compile-time if)
            if self.kind[j] == WALL:
                ref = w_wall
        ratio = kernels.w(r, self.h, self.dim) / ref
        return vj * (1.0 + 0.2 * ratio**4) * gw

    @ti.func
    def _shift_coefficient(self, i):
        """The shift's A at particle i: isph.ground_shifting for water in porous ground (eps_i < 1), else
        isph.shifting (the two are the same unless ground_shifting is given)."""
        a = self.shift_a
        if ti.static(self.porous and self.shift_a_ground != self.shift_a):  # noqa: SIM102 (compile-time if)
            if self.eps[i] < 1.0:
                a = self.shift_a_ground
        return a

    @ti.func
    def _shift(self, i, frac):
        """The shifting displacement over the fraction frac of the step dt: dr = -A h |u| frac dt grad C
        (grad C with Lind's anti-pairing term), with its component along the surface normal n = -grad C /
        |grad C| removed for particles within the support of a free-surface particle, and capped at frac
        shifting_max."""
        u = self._advection_velocity(i)
        gc = self.grad_c[i]
        ds = -self._shift_coefficient(i) * self.h * u.norm() * (frac * self.dt[None]) * gc
        near_surface = self.free[i]
        for k in range(self.grid.nbr_count[i]):
            j = self.grid.nbr[i, k]
            if self.kind[j] == WATER and self.free[j] == 1:
                near_surface = 1
        if near_surface == 1 and gc.norm() > 0.0:
            nrm = -gc.normalized()
            ds -= ds.dot(nrm) * nrm
        mag = ds.norm()
        cap = self.shift_max * frac
        if mag > cap:
            ds *= cap / mag
        return ds

    @ti.kernel
    def _k_shift_number(self) -> float:
        """The shifting's diffusion number A |u| dt / h over the water in the ground (eps < 1), largest."""
        nu = 0.0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1 and self.eps[i] < 1.0:
                ti.atomic_max(nu, self._shift_coefficient(i) * self._advection_velocity(i).norm() * self.dt[None]
                              / self.h)
        return nu

    @ti.kernel
    def _k_grad_c(self):
        """grad C (with the anti-pairing term) at the particles' present positions, as `_k_density` takes
        it at the step's start, for a shifting substep."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                gc = ti.Vector.zero(float, self.dim)
                w_ref = self._anti_pairing_reference(i)
                w_wall = self._wall_anti_pairing_reference(i)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if self._present(j) and r > 0.0:
                        gc += self._grad_c_pair(j, self._volume(j), r, kernels.grad_w(rij, r, self.h, self.dim), w_ref,
                                                w_wall)
                self.grad_c[i] = gc

    @ti.kernel
    def _k_shift(self, frac: float):
        """A later shifting substep: x += the shift of `_shift` over the fraction frac of the step."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                self.x[i] += self._shift(i, frac)
                if ti.static(self.periodic):
                    self.x[i] = operators.wrap(self.x[i], self.period)
