"""Stabilized ISPH step (seed 000 section 3) on the unified Navier-Stokes / extended Darcy form.

One step (projection method, eqs 18-31), all particles water or wall:
1. neighbour search (cell-sorted grid, lists for water particles); number density
   <rho_i> = sum_j m_j W_ij (eq 27, walls counted with a water particle's mass, lattice-normalised);
   free surface N_i < eps_i N_surf (eq 34); kernel-gradient correction matrix L_i.
2. predictor (eq 19): v* = v + c (g/eps + nu_E lap v) with c = eps dt / Cr, the viscous term by the
   variable-viscosity Laplacian eq 22 (Smagorinsky nu_T of eq 3 only when enabled).
3. PPE (eq 31) in symmetric form  div(k grad P)_i = div v*_i + alpha eps_i (rho_bar_i - <rho_i>) /
   (rho_bar_i dt), k = c / rho_bar (eq 24 Laplacian with the pairwise mean of rho_bar k). With
   eps = 1 and k = dt / rho_w this is eq 31 divided by rho_w / dt. Free-surface rows are Dirichlet.
   Walls: a wall particle seen from i carries P_i + rho_w g . (x_w - x_i) (Neumann with hydrostatic
   correction), so walls add only known terms and the matrix stays symmetric positive definite.
4. corrector (eq 20): v = v* - k grad P, gradient eq 12 with kernel-gradient correction by default;
   walls carry P_i hydrostatic across the wall and the water's own gradient along its face.
5. advection x += dt v / eps (pore velocity) or dt v (Darcy velocity, `advection: darcy`).

The kernels loop over each particle's neighbours (`_pair`; `_volume` and `_mass_and_density` say what a
water or wall neighbour stands for) and call the terms of terms.py; walls are sph/walls.py's. Three parts
of the step are mixins of ISPHSolver, each in its own module: surface.py (the free-surface tests beyond
eq 34's count: closed bodies, the cone test in the ground), shifting.py (the particle shift) and
ground_density.py (what pore water's number density is measured against in eq 31 and the surface tests).
"""


import logging
import math
import time as _time

import numpy as np
import taichi as ti

from .. import guard
from ..backend import check_field_room, is_f64, on_cpu
from ..errors import InputError, InstabilityError
from ..linalg.ell_pcg import EllOverflowError, EllPCG
from ..linalg.mg_pcg import MGPCG
from ..linalg.sparse_cg import SparseCGSolver
from ..scene import WALL, WATER
from ..sph import kernels, operators, walls
from ..sph.grid import NeighbourGrid, NeighbourOverflowError
from ..sph.scan import PrefixSum
from ..sph.solver_common import SolverCommon
from ..sph.wall_motion import WallMotion
from . import porosity as _porosity
from . import terms
from .ground_density import GroundDensity
from .shifting import SHIFT_NUMBER_MAX, SHIFT_SUBSTEPS_MAX, Shifting
from .surface import SurfaceTests

log = logging.getLogger("taichi_sph")

GRAD_CORRECTED, GRAD_DIFFERENCE, GRAD_SYMMETRIC = 0, 1, 2
#: most re-solves of the PPE per step after freeing water held in tension (_k_tension)
TENSION_PASSES = 3
#: inside saturated ground the kernel-gradient correction is kept where the implicit drag D = 1 + c (a + b |v|)
#: is at least this: the projection's overshoot, up to 1 / lambda_min(M_i) ~ 3-5 on disordered pore water,
#: carries into the next step divided by D (_k_corrector)
DRAG_CORRECTED = 5.0
#: flags of a vertical wall particle in _k_wet: water within its support reaches its height (not more than
#: 0.6 dx below it), and not all of that water hangs above it (some within 0.6 dx above it or lower)
WET_REACHED, WET_NOT_HANGING = 2, 4
#: on the CPU, a scene of at most this many particles (water, walls and all) runs every loop of the step
#: serially on the calling thread (`self.serial`), as EllPCG does below its SERIAL_ROWS: a parallel loop
#: hands its work to Taichi's thread pool and waits for it, which costs more than a small loop's own work.
#: Wall ms per step on 2 cores (AMD EPYC), parallel / serial: permeameter dx 5 mm (2.0k particles)
#: 14.0-15.2 / 9.1-9.2, coarse free fall (3D, 7.2k) 16-19 / 11-12; the two meet above the bound: porous
#: dam break dx 3.5 mm (2D, 10.4k) 102-121 / 112-123, free fall dx 1.5 cm (3D, 12.3k) 18-26 / 21-25
#: (docs/performance.md, "Small scenes run serially")
SERIAL_PARTICLES = 8192
_GRAD = {"corrected": GRAD_CORRECTED, "difference": GRAD_DIFFERENCE, "symmetric": GRAD_SYMMETRIC}


@ti.data_oriented
class ISPHSolver(SurfaceTests, Shifting, GroundDensity, SolverCommon):
    """State and step of mode `isph`. Built from a validated Config and a Scene."""

    #: the density the guard checks (guard_fields): the same as fields_by_id reports
    density_field = "rho_n"

    #: the per-step diagnostics step() reports (run.DIAG_COLUMNS lists every mode's)
    diagnostic_names = ("kinetic_energy", "max_speed", "water_volume", "cg_iterations", "cg_residual",
                        "free_surface", "collisions", "isolated", "closed_bodies", "shift_substeps", "pressure_min")

    @property
    def n_fluid(self) -> int:
        """Fluid particles a step moves: the water (mode isph has no air)."""
        return self.n_water

    def __init__(self, cfg, scene):
        check_field_room()  # a clear error, not Taichi's crash, where the runtime's field trees run out
        self.cfg = cfg
        self.dim = dim = cfg.dim
        self.dx = dx = cfg.dx
        self.re = kernels.SUPPORT_FACTOR * dx
        self.h = 0.5 * self.re
        self.eta2 = 1.0e-4 * self.h**2
        self.rho_w = cfg.fluid.density
        self.nu = cfg.fluid.viscosity
        self.cs_delta2 = (cfg.fluid.smagorinsky_cs * self.re) ** 2
        self.mass = self.rho_w * dx**dim
        lat = kernels.lattice_sums(dim)
        self.kernel_sum = lat["kernel_sum"]
        self.g_np = np.asarray(cfg.gravity_vector(), dtype=float)
        self.g_abs = float(np.linalg.norm(self.g_np))
        self.alpha = cfg.isph.alpha
        self.n_surf = cfg.n_surf()
        self.p_surface = 0.5 * self.rho_w * self.g_abs * dx if cfg.isph.free_surface_pressure == "half_layer" else 0.0
        self.surface_density = cfg.isph.surface_density
        # ti.static switches: a scene compiles only what it uses (taichi_sph/switches.py, also what
        # `taichi-sph info --config` reports)
        from ..switches import Switches

        self.switches = sw = Switches.build(cfg, scene)
        self.turbulence = sw.turbulence
        self.no_slip = sw.no_slip
        self.grad_mode = _GRAD[sw.gradient]
        self.pore_advection = sw.pore_advection
        # porous ground only when the scene has soil markers (ti.static: otherwise compiled out)
        self.porous = sw.porous
        # pore water holds no suction beyond the ground's air-entry value (isph.air_entry_suction)
        self.suction_floor = float(cfg.isph.air_entry_suction) if sw.air_entry else 0.0
        self.alpha_c = cfg.soil.alpha_c
        self.beta_c = cfg.soil.beta_c
        # surface test in and next to the ground: the count's candidates confirmed by an empty cone
        self.ground_cone = sw.ground_cone
        self.cone_cos = math.cos(math.radians(cfg.isph.ground_surface_cone))
        self.ground_beta = float(cfg.isph.ground_surface_density)
        # free water next to the ground held in tension becomes free surface (_k_tension)
        self.ground_tension = sw.ground_tension
        self.tension_fill = float(cfg.isph.ground_tension_fill)
        # a candidate in tension that was free surface at the end of the last step is freed again
        self.tension_memory = sw.tension_memory
        # drained pore water is a candidate of the cone test (_k_surface_cone)
        self.drained_candidate = sw.ground_drained
        # eq 31's stabilisation reads pore water over the pore lattice's support (_k_pore_density)
        self.pore_density = sw.pore_density
        # ... only where that support lies in uniform ground (isph.ground_density_support interior)
        self.pore_interior = sw.pore_interior
        # kernel-gradient correction in the ground (L_i = M_i^-1 where eps_i < 1), else plain eq 12 there
        self.ground_correction = sw.ground_correction
        #: candidate of the cone test (in or next to the ground): eq 34's count or the plain count marks it,
        #: whatever its cone said (_k_tension reads it)
        self.candidate = ti.field(ti.i32, scene.n)
        #: water that _k_tension frees in this pass (held in tension, with air within its support)
        self.air_entry_now = ti.field(ti.i32, scene.n)
        self.shifting = sw.shifting
        self.shift_a = cfg.isph.shifting
        #: the shift's coefficient for water in porous ground (isph.ground_shifting, else isph.shifting)
        self.shift_a_ground = cfg.isph.shifting if cfg.isph.ground_shifting is None else cfg.isph.ground_shifting
        self.shift_max = cfg.isph.shifting_max * dx
        self.w_dx = kernels.sigma(dim, self.h) * _spline(dx / self.h)
        self.collision = sw.collisions
        self.r_coll = cfg.isph.collision_distance * dx
        self.restitution = cfg.isph.collision_restitution

        self.n = scene.n
        self.n_water = scene.count(WATER)
        #: period of each axis (0.0: not periodic), for operators.rel and operators.wrap
        self.period = scene.periods()
        self.periodic = sw.periodic
        n = self.n
        #: the step's loops run serially on the calling thread (SERIAL_PARTICLES; never on a GPU)
        self.serial = on_cpu() and n <= SERIAL_PARTICLES
        self.max_nb = cfg.max_neighbours()
        self.ppe_widenings = 0  # times the ELL PPE matrix was widened after a row overflow
        vec = ti.types.vector(dim, float)
        self.x = ti.Vector.field(dim, float, n)
        self.v = ti.Vector.field(dim, float, n)
        self.vstar = ti.Vector.field(dim, float, n)
        self.normal = ti.Vector.field(dim, float, n)
        self.p = ti.field(float, n)
        self.rho_n = ti.field(float, n)
        self.eps = ti.field(float, n)
        self.kcoef = ti.field(float, n)
        self.d50 = ti.field(float, n)
        #: 1 where a soil marker of porosity below 1 lies within the support (eq 32's reach), else 0
        self.ground_reach = ti.field(ti.i32, n)
        self.drag = ti.field(float, n)
        #: rest fill of water that starts in or next to ground: its <rho> / rho_bar at t = 0
        self.rest_fill = ti.field(float, n)
        self.rest_fill.fill(1.0)
        #: with isph.ground_density_support pore: pore water's <rho> over the pore lattice's support, its
        #: rest fill (over the packing of the block it was placed in, `packing`, read at t = 0)
        self.rho_pore = ti.field(float, n)
        #: 1 where eq 31 reads rho_pore (with interior: the support in uniform ground), 0 where it reads r_e
        self.pore_read = ti.field(ti.i32, n)
        self.rest_fill_pore = ti.field(float, n)
        self.rest_fill_pore.fill(1.0)
        self.packing = ti.field(float, n)
        self._scene_packing = np.ones(n) if scene.packing is None else np.asarray(scene.packing, float)
        #: the free-surface flag at the end of the last step (_k_surface_cone reads it: air's path)
        self.air_last = ti.field(ti.i32, n)
        self.nu_t = ti.field(float, n)
        self.L = ti.Matrix.field(dim, dim, float, n)
        self.kind = ti.field(ti.i32, n)
        self.ids = ti.field(ti.i32, n)
        self.active = ti.field(ti.i32, n)
        self.free = ti.field(ti.i32, n)
        #: 1 for a water particle with no water neighbour within its support (spray, a lone drop)
        self.isolated = ti.field(ti.i32, n)
        self.solve_mask = ti.field(ti.i32, n)
        self.row = ti.field(ti.i32, n)
        self._row_scan = PrefixSum(n)
        self.row_flag = ti.field(ti.i32, n if self._row_scan.blocked else 1)
        self.row_start = ti.field(ti.i32, n + 1 if self._row_scan.blocked else 1)
        self.b = ti.field(float, max(self.n_water, 1))
        self.psol = ti.field(float, max(self.n_water, 1))
        self.triplets = ti.field(ti.i32, ())
        #: Dirichlet rows of the last assembly; none (closed or periodic box full of water): the PPE is
        #: singular up to a constant and is solved for zero-mean pressure
        self.dirichlet_rows = ti.field(ti.i32, ())
        self.vtmp = ti.Vector.field(dim, float, n)
        #: water bodies (connected by water pairs within the support) without a Dirichlet row:
        #: label (the lowest index in the body), per label whether it has a free-surface particle,
        #: whether it is still joined to another label, and its particle with the fewest neighbours
        self.body = ti.field(ti.i32, n)
        self.body_free = ti.field(ti.i32, n)
        self.body_open = ti.field(ti.i32, n)
        self.body_pick = ti.field(ti.i64, n)
        self.body_size = ti.field(ti.i32, n)
        #: per neighbour slot whether the pair is water of one body (_water_pair), read once per step by
        #: _k_body_init and then by every sweep
        self.body_link = ti.field(ti.i8, (n, self.max_nb) if self.porous else (1, 1))
        #: each water particle's own reach of the pair test (_body_reach), taken once per step
        self.body_reach = ti.field(float, n if self.porous else 1)
        self.closed_bodies = ti.field(ti.i32, ())
        self.body_changed = ti.field(ti.i32, ())
        self.any_free = ti.field(ti.i32, ())
        self.grad_c = ti.Vector.field(dim, float, n)
        #: pressure gradient of a water particle next to a wall, from its water neighbours (corrected
        #: eq 12): the wall pressure's variation along the wall face (_wall_pressure_seen)
        self.grad_p_water = ti.Vector.field(dim, float, n)
        self.wet = ti.field(ti.i32, n)
        self.dry_walls = sw.dry_walls
        self.up = vec((-self.g_np / max(self.g_abs, 1e-300)).tolist())
        self.collisions = ti.field(ti.i32, ())
        self.dt = ti.field(float, ())
        self.g = vec(self.g_np.tolist())
        self.particle_fields = [self.x, self.v, self.normal, self.p, self.eps, self.kind, self.ids, self.active]
        if self.porous:
            self.particle_fields += [self.rest_fill, self.air_last]
            if self.pore_density:
                self.particle_fields.append(self.rest_fill_pore)

        self.np_fp = np.float64 if is_f64() else np.float32
        self.x.from_numpy(scene.position.astype(self.np_fp))
        self.normal.from_numpy(scene.normal.astype(self.np_fp))
        self.kind.from_numpy(scene.kind.astype(np.int32))
        self.ids.from_numpy(scene.ids)
        self.active.fill(1)
        self.eps.fill(1.0)
        self.v.fill(0.0)
        if scene.velocity is not None:
            self.v.from_numpy(scene.velocity.astype(self.np_fp))
        self.p.fill(0.0)
        # obstacles with a prescribed motion (sph/wall_motion.py): their wall velocity enters the wall
        # conditions through self.v of the wall particles
        self.motion = WallMotion(scene, dim, self.period)
        self.wall_body = self.motion.body
        self.wall_origin = self.motion.origin
        self.particle_fields += self.motion.fields()

        self.grid = NeighbourGrid(n, dim, scene.lo, scene.hi, self.re, self.max_nb, period=self.period,
                                  serial=self.serial)
        self.wall_pressure = walls.WallPressure(self, n)
        self.markers = None
        if self.porous:
            self.markers = _porosity.MarkerSet(scene.markers, dim, scene.lo, scene.hi, self.re, serial=self.serial)
            eps_tab, k_tab, n_tab = _porosity.lattice_table(dim)
            self.ksum_eps0 = float(eps_tab[0])
            self.ksum_deps = float(eps_tab[1] - eps_tab[0])
            self.ksum_n = len(eps_tab)
            self.ksum = ti.field(float, len(eps_tab))
            self.ksum.from_numpy(k_tab.astype(self.np_fp))
            # eq 34 in the ground: N_i < N_surf N(eps) / N(1), N(eps) the pore lattice's count
            self.nsurf_tab = ti.field(float, len(eps_tab))
            self.nsurf_tab.from_numpy((self.n_surf * n_tab / n_tab[-1]).astype(self.np_fp))
        fp = ti.f64 if is_f64() else ti.f32
        # PPE solver (ti.static switch in the assembly): ELL matrix + Jacobi-PCG or multigrid-PCG (its
        # levels the neighbour grid's cells), or the sparse builder
        self.ppe_ell = sw.ppe_ell
        if self.ppe_ell:
            ppe_args = (max(self.n_water, 1), ppe_width(cfg), cfg.isph.ppe.tolerance, cfg.isph.ppe.max_iterations)
            if cfg.isph.ppe.type == "mg_pcg":
                self.ppe = MGPCG(*ppe_args, dtype=ppe_precision(cfg.isph.ppe, fp), cells=self.grid.ncell,
                                 periodic=[p > 0.0 for p in self.grid.period], source=(self.grid.cell, self.row))
            else:
                self.ppe = EllPCG(*ppe_args, dtype=ppe_precision(cfg.isph.ppe, fp))
            # the right-hand side and the solution live in the solver's fields (no host copies)
            self.b = self.ppe.b
            self.psol = self.ppe.x
        else:
            check_sparse_cg_backend(cfg.isph.ppe, on_cpu())
            self.ppe = SparseCGSolver(max(self.n_water, 1), max(self.n_water, 1) * (self.max_nb + 1), fp,
                                      cfg.isph.ppe.tolerance, cfg.isph.ppe.max_iterations)
        #: floats of the PPE matrix (the ELL solver's; the run's for the sparse builder): a row's diagonal is
        #: summed in them from the off-diagonals it stores, so that a box without a Dirichlet row has the
        #: constants as its exact null space. Summed in f32 (a run at f32, the PPE at f64) the rows of the
        #: periodic Taylor-Green box summed to 2.7e-7 of the largest entry, and CG stopped at a relative
        #: residual of 0.05 on its first step
        self.ppe_fp = self.ppe.dtype if self.ppe_ell else fp
        self.dirichlet_scale = self._lattice_laplacian_sum()
        self.removed_total = 0
        self.step_count = 0
        self.time = 0.0
        self.timers = {k: 0.0 for k in ("neighbours", "porosity", "density", "predictor", "ppe_assembly", "ppe_solve",
                                         "corrector", "diagnostics")}
        self.last = {}

    # ------------------------------------------------------------------ helpers
    def _lattice_laplacian_sum(self) -> float:
        """sum_j V_j |F_ij| over a full lattice: a typical PPE diagonal per unit k (scales Dirichlet rows)."""
        d, h, dx = self.dim, self.h, self.dx
        m = int(math.ceil(kernels.SUPPORT_FACTOR)) + 1
        rng = np.arange(-m, m + 1) * dx
        pts = np.stack([g.ravel() for g in np.meshgrid(*([rng] * d), indexing="ij")], axis=1)
        r = np.linalg.norm(pts, axis=1)
        r = r[(r > 0) & (r < self.re)]
        f = -kernels.dw_dr_np(r, h, d) * r / (r * r + self.eta2)
        return float(2.0 * dx**d * f.sum())

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _k_rows(self):
        """Row numbering of the PPE (water particles in current order) and the neighbour-list mask. A running
        count on the CPU; on GPUs a blocked prefix sum of the water flags (sph/scan.py), the same numbers."""
        if ti.static(self._row_scan.blocked):
            for i in range(self.n):
                self.row_flag[i] = 1 if self.kind[i] == WATER else 0
            self._row_scan.exclusive(self.row_flag, self.row_start, self.n)
            for i in range(self.n):
                self.row[i] = -1
                self.solve_mask[i] = 0
                if self.kind[i] == WATER:
                    self.row[i] = self.row_start[i]
                    if self.active[i] == 1:
                        self.solve_mask[i] = 1
        else:
            ti.loop_config(serialize=True)
            c = 0
            for i in range(self.n):
                self.row[i] = -1
                self.solve_mask[i] = 0
                if self.kind[i] == WATER:
                    self.row[i] = c
                    c += 1
                    if self.active[i] == 1:
                        self.solve_mask[i] = 1

    @ti.kernel
    def _k_wet(self):
        """Dry walls. A wall particle of a vertical wall (|n . up| < 1/2) that no water particle within its
        support reaches in height (z_water >= z_wall - 0.6 dx) stands in air above the waterline: it is
        left out of every sum (number density, free-surface count, PPE, gradient, viscosity), as air is;
        so is one that all water within its support hangs above (more than 0.6 dx higher, with no floor
        below it within its support: water resting on a floor reaches the wall layers beside the floor):
        a wall below water held in porous ground, which counted as wet blocked the free-surface cones of a
        draining slab's lower corners (Darcy column at dx 2 cm 3.6 % slow).
        Counting it would fill the missing air above surface particles along a wall, most of all in a
        corner where two walls rise above the water, so that those particles are not found free.
        Floors, ceilings and obstacle tops (|n . up| >= 1/2) are always wet."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.kind[i] == WALL:
                w = 1
                if ti.static(self.dry_walls):
                    if ti.abs(self.normal[i].dot(self.up)) < 0.5:
                        w = 0
                self.wet[i] = w
        if ti.static(self.dry_walls):
            ti.loop_config(serialize=self.serial)
            for i in range(self.n):
                if self.solve_mask[i] == 1:
                    xi = self.x[i]
                    # water with a floor (an upward-facing wall) below it within its support rests on it
                    rests = False
                    for k in range(self.grid.nbr_count[i]):
                        j = self.grid.nbr[i, k]
                        if self.kind[j] == WALL and self.normal[j].dot(self.up) >= 0.5:
                            if operators.rel(xi, self.x[j], self.period).dot(self.up) > 0.0:
                                rests = True
                    for k in range(self.grid.nbr_count[i]):
                        j = self.grid.nbr[i, k]
                        if self.kind[j] == WALL and self.wet[j] != 1:
                            dz = operators.rel(xi, self.x[j], self.period).dot(self.up)
                            if dz >= -0.6 * self.dx:
                                ti.atomic_or(self.wet[j], WET_REACHED)
                            if rests or dz <= 0.6 * self.dx:
                                ti.atomic_or(self.wet[j], WET_NOT_HANGING)
            ti.loop_config(serialize=self.serial)
            for i in range(self.n):
                if self.kind[i] == WALL and self.wet[i] != 1:
                    self.wet[i] = 1 if self.wet[i] == WET_REACHED | WET_NOT_HANGING else 0

    @ti.func
    def _table_at(self, table: ti.template(), eps):
        """A porosity.lattice_table column at eps, linearly interpolated."""
        t = (eps - self.ksum_eps0) / self.ksum_deps
        k = ti.min(ti.max(ti.cast(ti.floor(t), ti.i32), 0), self.ksum_n - 2)
        f = ti.min(ti.max(t - k, 0.0), 1.0)
        return (1.0 - f) * table[k] + f * table[k + 1]

    @ti.func
    def _present(self, j):
        """Neighbour j takes part in the sums: water, or a wet wall particle."""
        return self.kind[j] != WALL or self.wet[j] == 1

    @ti.func
    def _pair(self, i, k, xi):
        """The k-th listed neighbour j of particle i (at xi), rij = x_i - x_j (minimum image), r = |rij|."""
        j = self.grid.nbr[i, k]
        rij = operators.rel(xi, self.x[j], self.period)
        return j, rij, rij.norm()

    @ti.func
    def _volume(self, j):
        """Bulk volume V_j a neighbour stands for: m / (eps_j rho_w) for water (a water particle in ground
        fills 1 / eps_j lattice cells), the lattice cell dx^d = m / rho_w for a wall particle."""
        vj = self.mass / self.rho_w
        if self.kind[j] == WATER:
            vj = self.mass / (self.eps[j] * self.rho_w)
        return vj

    @ti.func
    def _mass_and_density(self, i, j):
        """Mass m_j and reference density rho_bar_j neighbour j carries in i's momentum and PPE sums: its
        own (m, eps_j rho_w) for water; a wall particle stands for water at i's porosity (eps_i m,
        eps_i rho_w), the seed's virtual-marker idea."""
        m_j = self.eps[i] * self.mass
        rb_j = self.eps[i] * self.rho_w
        if self.kind[j] != WALL:
            m_j = self.mass
            rb_j = self.eps[j] * self.rho_w
        return m_j, rb_j

    @ti.kernel
    def _k_density(self):
        """<rho_i> (eq 27), free-surface flag (eq 34) and the kernel-gradient correction L_i."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                wsum = kernels.w(0.0, self.h, self.dim)
                M = ti.Matrix.zero(float, self.dim, self.dim)
                gc = ti.Vector.zero(float, self.dim)
                n_water = 0
                nb = 0.0
                w_ref = self._anti_pairing_reference(i)
                w_wall = self._wall_anti_pairing_reference(i)
                # eq 34 counts eps N_surf; a pore lattice holds fewer neighbours than eps N_full
                # (2D, eps = 0.3: 4 within r_e, below 0.3 x 17 = 5.1, so every particle would be
                # free): the threshold scales with the pore lattice's own count instead
                n_surf = self.eps[i] * self.n_surf
                # a wall particle counts as the same fraction N(eps_i) / N(1) of a neighbour, so that
                # walls filling half the support count half the threshold's lattice. Counted as eps_i
                # (0.8 against N(0.8) / N(1) = 32 / 56 in 3D, where a lattice shell has left the
                # support) the walls alone held a lone particle in a corner above the threshold, and
                # its pressure row, with one water neighbour against 34 walls, gave it 100 kPa
                wall_count = 1.0
                if ti.static(self.porous):
                    if self.eps[i] < 1.0:
                        n_surf = self._table_at(self.nsurf_tab, self.eps[i])
                        if ti.static(self.n_surf > 0):
                            wall_count = n_surf / self.n_surf
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if not self._present(j):
                        continue
                    share = self._density_share(i, j)
                    count = wall_count
                    vj = self._volume(j)
                    if self.kind[j] == WATER:
                        n_water += 1
                        count = share
                    nb += count
                    wsum += share * kernels.w(r, self.h, self.dim)
                    if r > 0.0:
                        gw = kernels.grad_w(rij, r, self.h, self.dim)
                        M += terms.moment_pair(vj, rij, gw)
                        if ti.static(self.shifting):
                            gc += self._grad_c_pair(j, vj, r, gw, w_ref, w_wall)
                ksum = self.kernel_sum
                if ti.static(self.porous):
                    if self.eps[i] < 1.0:
                        ksum = self._table_at(self.ksum, self.eps[i])
                self.rho_n[i] = self.mass * wsum / ksum
                if ti.static(self.shifting):
                    self.grad_c[i] = gc
                is_free = 0
                if nb < n_surf or n_water == 0:
                    is_free = 1
                    # free water: a count below N_surf with a full number density is a particle
                    # inside the water whose outer ring has spread (Koshizuka & Oka's beta test)
                    if n_water > 0 and self.surface_density > 0.0 and self.eps[i] >= 1.0 and \
                            self.rho_n[i] >= self.surface_density * self.rho_w:
                        is_free = 0
                self.free[i] = is_free
                self.isolated[i] = 1 if n_water == 0 else 0
                Li = ti.Matrix.identity(float, self.dim)
                if ti.static(self.grad_mode == GRAD_CORRECTED):
                    det = M.determinant()
                    if det > 0.1:
                        Li = M.inverse()
                self.L[i] = Li

    @ti.kernel
    def _k_eddy_viscosity(self):
        """Smagorinsky eddy viscosity nu_T = (Cs Delta)^2 |S| (eq 3), S from a corrected eq 12 gradient."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                vi = self.v[i]
                G = ti.Matrix.zero(float, self.dim, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if not self._present(j):
                        continue
                    vj = self.v[j]
                    if self.kind[j] == WALL:
                        vj = walls.mirror_velocity(vi, self.v[j], self.normal[j], self.no_slip)
                    if r > 0.0:
                        gw = kernels.grad_w(rij, r, self.h, self.dim)
                        G += self._volume(j) * (vj - vi).outer_product(gw)
                self.nu_t[i] = terms.smagorinsky_viscosity(self.cs_delta2, G @ self.L[i].transpose())

    @ti.func
    def _eddy_viscosity(self, i):
        """nu_T of particle i (eq 3), 0 without turbulence."""
        nu_t = 0.0
        if ti.static(self.turbulence):
            nu_t = self.nu_t[i]
        return nu_t

    @ti.kernel
    def _k_predictor(self):
        """Predictor (eq 19) with the drag implicit in the whole projection (SPEC 3 step 2):
        c = eps dt / Cr, D = 1 + c (a + b |vD|),  v* = (vD + c (g / eps + nu_E lap vD)) / D  and the
        PPE / corrector coefficient k = c / (D rho_bar), so that vD(n+1) = v* - k grad P equals
        (vD + c (g / eps + nu_E lap vD) - c grad P / rho_bar) / D. Viscous term by eq 22; its wall pairs
        take nu_w / eps without the eddy viscosity (the Smagorinsky model has no wall damping). With
        eps = 1: Cr = 1, a = b = 0, D = 1 (plain Navier-Stokes)."""
        dt = self.dt[None]
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                vi = self.v[i]
                eps_i = self.eps[i]
                rb_i = eps_i * self.rho_w
                nu_i = terms.effective_viscosity(self.nu, self._eddy_viscosity(i), eps_i)
                lap = ti.Vector.zero(float, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if not self._present(j):
                        continue
                    if r > 0.0:
                        f = operators.laplacian_weight(r, self.h, self.eta2, self.dim)
                        vj = self.v[j]
                        nu_j = nu_i
                        m_j, rb_j = self._mass_and_density(i, j)
                        nu_ij = nu_i
                        if self.kind[j] == WALL:
                            # the wall's shear with the water's own viscosity, no eddy viscosity
                            # (docs/isph.md, "No eddy viscosity in the wall's shear")
                            vj = walls.mirror_velocity(vi, self.v[j], self.normal[j], self.no_slip)
                            nu_ij = terms.effective_viscosity(self.nu, 0.0, eps_i)
                            nu_j = nu_ij
                        else:
                            nu_j = terms.effective_viscosity(self.nu, self._eddy_viscosity(j), self.eps[j])
                        lap += terms.viscous_pair(m_j, rb_i, nu_ij, rb_j, nu_j, f, vi, vj)
                c = eps_i * dt
                drag = 1.0
                if ti.static(self.porous):
                    if eps_i < 1.0:
                        c /= _porosity.inertia_coefficient(eps_i)
                        drag = terms.drag_factor(eps_i, self.nu, self.d50[i], vi.norm(), c, self.alpha_c,
                                                 self.beta_c)
                self.vstar[i] = terms.predicted_velocity(vi, c, self.g, eps_i, lap, drag)
                self.kcoef[i] = c / (drag * rb_i)
                if ti.static(self.porous):
                    self.drag[i] = drag

    @ti.kernel
    def _k_assemble(self, A: ti.types.sparse_matrix_builder()):
        """The PPE into a SparseMatrixBuilder (isph.ppe.type sparse_cg)."""
        self._assemble(A)

    @ti.kernel
    def _k_assemble_ell(self, ell: ti.template()):
        """The PPE into the ELL matrix of EllPCG `ell` (isph.ppe.type ell_pcg); a template argument, so
        that a wider matrix after a row overflow compiles its own kernel."""
        self._assemble(ell)

    @ti.func
    def _ppe_add(self, A: ti.template(), i, j, v):
        """A[i, j] += v in the PPE matrix of the configured solver (only row i's thread writes row i)."""
        if ti.static(self.ppe_ell):
            A.add(i, j, v)
        else:
            A[i, j] += v
            ti.atomic_add(self.triplets[None], 1)

    @ti.func
    def _assemble(self, A: ti.template()):
        """PPE rows (eq 31 in symmetric form, eq 23 divergence, eq 24 Laplacian); Dirichlet rows at the
        free surface (eq 34) and for inactive particles.

        Gravity enters through its potential: v* = v*_rest + k rho_w g with k rho_w g = k grad(phi),
        phi = rho_w g . x, so eq 31 is solved as Lap_k(P - phi) = div v*_rest / dt-form, i.e. the
        gravity part of the source is the same pair Laplacian as the pressure. A fluid at rest then has
        P = phi + const exactly, for any particle arrangement and any jump of k (free water over fine
        sand: k falls by D ~ 2000 across one layer, and the eq 23 divergence of the jump in k rho_w g
        does not match the eq 24 Laplacian of a linear P, which left the water above the sand falling
        freely). Walls follow the same split: P_w - phi_w = P_i - phi_i (the hydrostatic Neumann
        condition), so wall pairs add nothing but the mirrored v*_rest to the divergence.
        The one place the coefficients are computed, for both solver types."""
        dt = self.dt[None]
        dirichlet_diag = self.dirichlet_scale * dt / self.rho_w
        self.triplets[None] = 0
        self.dirichlet_rows[None] = 0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.kind[i] == WATER:
                ri = self.row[i]
                if ti.static(self.ppe_ell):
                    A.start_row(ri)
                if self.solve_mask[i] == 1 and self.free[i] == 0:
                    xi = self.x[i]
                    k_i = self.kcoef[i]
                    vi = self.vstar[i] - k_i * self.rho_w * self.g
                    eps_i = self.eps[i]
                    rb_i = eps_i * self.rho_w
                    div = 0.0
                    diag = ti.cast(0.0, self.ppe_fp)
                    rhs = 0.0
                    for k in range(self.grid.nbr_count[i]):
                        j, rij, r = self._pair(i, k, xi)
                        if not self._present(j):
                            continue
                        if r > 0.0:
                            gw = kernels.grad_w(rij, r, self.h, self.dim)
                            f = operators.laplacian_weight(r, self.h, self.eta2, self.dim)
                            m_j, rb_j = self._mass_and_density(i, j)
                            if self.kind[j] == WALL:
                                # impermeability only: the wall's image reverses the velocity normal to it
                                # (relative to the wall), slip or no-slip; the tangential no-slip condition
                                # belongs to the viscous term. With the whole velocity reversed, a no-slip
                                # wall moving along its face put a source 2 m v_w . grad W into every row
                                # whose wall neighbours are not symmetric about it (near a free surface)
                                vj = walls.mirror_velocity(vi, self.v[j], self.normal[j], False)
                                div += terms.divergence_pair(m_j, vi, vj, gw)
                            else:
                                vj = self.vstar[j] - self.kcoef[j] * self.rho_w * self.g
                                div += terms.divergence_pair(m_j, vi, vj, gw)
                                K = terms.ppe_pair(m_j, rb_i, k_i, rb_j, self.kcoef[j], f)
                                diag += ti.cast(K, self.ppe_fp)
                                rhs += K * self.rho_w * self.g.dot(rij)  # phi_i - phi_j
                                if self.free[j] == 1 or self.solve_mask[j] == 0:
                                    rhs += K * self._dirichlet_value(j)
                                else:
                                    self._ppe_add(A, ri, self.row[j], -K)
                    div /= rb_i
                    stab = terms.density_stabilisation(self.alpha, eps_i, self._rest_density(i), self.rho_n[i], dt)
                    if ti.static(self.pore_density):  # noqa: SIM102 (compiled only with the option)
                        if eps_i < 1.0 and self.pore_read[i] == 1:
                            stab = terms.density_stabilisation(self.alpha, eps_i, eps_i * self.rho_w
                                                               * self.rest_fill_pore[i], self.rho_pore[i], dt)
                    if ti.static(self.porous):
                        # the density error is relaxed through the same drag as the flow: without the
                        # 1 / D, fine sand (D ~ 300 at D50 = 0.1 mm) turns a 1 % density error into
                        # pressures of many rho g H
                        stab /= self.drag[i]
                    source = div + stab
                    self._ppe_add(A, ri, ri, diag)
                    self._set_rhs(A, ri, rhs - source)
                else:
                    ti.atomic_add(self.dirichlet_rows[None], 1)
                    self._ppe_add(A, ri, ri, dirichlet_diag)
                    self._set_rhs(A, ri, dirichlet_diag * self._dirichlet_value(i))

    @ti.func
    def _set_rhs(self, A: ti.template(), ri, v):
        """b[ri] = v: the ELL solver's own b, or the host-side b of the sparse-matrix path."""
        if ti.static(self.ppe_ell):
            A.b[ri] = ti.cast(v, A.b.dtype)
        else:
            self.b[ri] = ti.cast(v, self.b.dtype)

    @ti.func
    def _dirichlet_value(self, i):
        val = 0.0
        if self.solve_mask[i] == 1:
            val = self.p_surface
        return val

    @ti.kernel
    def _k_tension(self, psol: ti.template()) -> ti.i32:
        """Free water next to the ground that the PPE holds in tension becomes free surface: a candidate of
        the cone test (short of neighbours, but a neighbour in its cone) in free water (eps_i = 1) whose
        solved pressure is below the atmosphere's (P < 0) and which has a free-surface water particle
        within its support, or was free surface itself at the end of the last step (air_last, with
        isph.ground_tension_memory: the air that was at it stays while the water there is pulled; a drop
        hanging under the free fall's layer in a corner, its cones blocked by the walls it wets, lost every
        free-surface row in one step and was pulled at -182 kPa). Without capillarity water cannot be
        pulled: air enters where the projection would hold a thinning sheet together, but only from the
        air, through the surface: water with no surface in its support (the bottom of a column standing on
        a saturated plug, short of neighbours only because the pore water below it is sparse) is closed to
        the air and keeps its tension, which there is the transient of discrete particles entering the
        pores (docs/isph.md, "Surface test in the ground"). Air advances one support per pass. Returns how
        many were freed (the PPE is then solved again). Inside the ground (eps_i < 1) only pore water that
        has drained, <rho_i> below isph.ground_tension_fill of its rest value eps_i rho_w rest_fill_i, takes
        the rule (docs/isph.md, "Air into drained pores"): saturated pore water near a plug's exit face
        sits near zero pressure, and freeing its noise put Dirichlet rows into the plug."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.air_entry_now[i] = 0
            open_to_air = self.eps[i] >= 1.0
            if ti.static(self.porous):
                if self.eps[i] < 1.0:
                    open_to_air = self._drained(i)
            if self.solve_mask[i] == 1 and self.free[i] == 0 and self.candidate[i] == 1 and open_to_air:
                if psol[self.row[i]] < 0.0:
                    if ti.static(self.tension_memory):  # noqa: SIM102 (compiled only with the switch)
                        if self.air_last[i] == 1:  # air was at it at the end of the last step: it stays
                            self.air_entry_now[i] = 1
                    for k in range(self.grid.nbr_count[i]):
                        j = self.grid.nbr[i, k]
                        if self.kind[j] == WATER and self.free[j] == 1:
                            self.air_entry_now[i] = 1
        n_new = 0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.air_entry_now[i] == 1:
                self.free[i] = 1
                n_new += 1
        return n_new

    def _solve_tension(self, iters, res, ok, sol):
        """Up to TENSION_PASSES times: free the water held in tension (_k_tension) and solve again from the
        last pressure. Returns the summed iterations, the last residual and convergence, and the sparse
        path's solution."""
        for _ in range(TENSION_PASSES):
            if not ok or self._k_tension(self.psol) == 0:
                break
            sol, more, res, ok = self._solve_ppe(self._assemble_ppe(), sol)
            iters += more
        return iters, res, ok, sol

    def _assemble_ppe(self):
        """Assemble this step's PPE (eq 24) into the ELL matrix or the sparse builder; for the sparse path,
        return its right-hand side."""
        if self.ppe_ell:
            self._k_assemble_ell(self.ppe)
            return None
        self._k_assemble(self.ppe.builder)
        self.ppe.check_triplets(int(self.triplets[None]))
        self.ppe.build()
        return self.b.to_numpy()[: self.n_water]

    def _solve_ppe(self, b, x0):
        """Solve the assembled PPE into psol: the ELL path in place from the pressure in psol, the sparse one
        from x0 with the right-hand side b (its solution copied into psol). Returns (the sparse path's
        solution or None, iterations, residual, converged); zero mean where the water holds no Dirichlet
        row."""
        zero_mean = self.dirichlet_rows[None] == 0
        if self.ppe_ell:
            iters, res, ok = self.ppe.solve(self.n_water, zero_mean=zero_mean)
            return None, iters, res, ok
        sol, iters, res, ok = self.ppe.solve(b, x0, zero_mean=zero_mean)
        self.psol.from_numpy(sol.astype(self.np_fp))
        return sol, iters, res, ok

    @ti.kernel
    def _k_scatter_pressure(self, psol: ti.template()):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.kind[i] == WATER:
                pi = ti.cast(psol[self.row[i]], float)  # the PPE may solve in f64 (ppe_precision)
                if ti.static(self.suction_floor > 0.0):
                    if self.eps[i] < 1.0:
                        pi = ti.max(pi, -self.suction_floor)
                self.p[i] = pi

    @ti.kernel
    def _k_gather_pressure(self, psol: ti.template()):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.kind[i] == WATER:
                psol[self.row[i]] = ti.cast(self.p[i], psol.dtype)

    @ti.kernel
    def _k_water_gradient(self):
        """grad P of each water particle that has a wall neighbour, from its water neighbours only (eq 12
        difference form, corrected by their own moment matrix where it is invertible): what the wall
        pressure takes along the wall's face."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            near_wall = 0
            if self.solve_mask[i] == 1:  # the sums below only for a particle with a wall in its list
                for k in range(self.grid.nbr_count[i]):
                    if self.kind[self.grid.nbr[i, k]] == WALL:
                        near_wall = 1
                        break
            if near_wall == 1:
                xi = self.x[i]
                pi = self.p[i]
                M = ti.Matrix.zero(float, self.dim, self.dim)
                s = ti.Vector.zero(float, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if self.kind[j] != WALL and self.solve_mask[j] == 1:
                        if r > 0.0:
                            gw = kernels.grad_w(rij, r, self.h, self.dim)
                            vj = self._volume(j)
                            M += terms.moment_pair(vj, rij, gw)
                            s += vj * (self.p[j] - pi) * gw
                # corrected wherever the water spans every direction: a corner of the tank leaves a
                # quarter (3D: an eighth) of the support, eigenvalues near 1/4 and det ~ 0.02 in 3D;
                # a chain or a sheet of particles has det = 0 (there the plain sum, zero for a lone
                # particle)
                if M.determinant() > ti.static(0.1**self.dim):
                    s = M.inverse() @ s
                self.grad_p_water[i] = s

    @ti.func
    def _wall_source(self, i):
        """Whether particle i gives the wall particles it sees a pressure (walls.WallPressure): water in
        the solve."""
        return self.solve_mask[i] == 1

    @ti.func
    def _own_wall_pressure(self, i, j, d):
        """Pressure that water particle i gives wall particle j, d = x_j - x_i (virtual-marker idea of the
        seed): walls.wall_pressure_along_face, hydrostatic across the wall and the water's own gradient
        along it. The corrector takes it for each pair; its weighted mean is the wall pressure of the run
        file (_wall_pressure_seen)."""
        return walls.wall_pressure_along_face(self.p[i], self.rho_w, self.g, self.grad_p_water[i], self.normal[j], d)

    @ti.func
    def _wall_pressure_seen(self, i, j):
        """Kernel weight and pressure (_own_wall_pressure) that water particle i gives wall particle j;
        weight 0 for a dry wall."""
        wij = 0.0
        pw = 0.0
        if self._present(j):
            d = -operators.rel(self.x[i], self.x[j], self.period)
            wij = kernels.w(d.norm(), self.h, self.dim)
            pw = self._own_wall_pressure(i, j, d)
        return wij, pw

    @ti.kernel
    def _k_corrector(self):
        """v = v* - k grad P (eq 20), gradient by eq 12 (optionally corrected) or eq 13.

        The gradient is the operator's own gradient of P: gravity (in v*) is balanced only by the
        pressure differences a particle's neighbours carry. The PPE is solved for P - phi (phi =
        rho_w g . x, see _assemble), but the corrector does not take phi's gradient out as the exact
        rho_w g: that would credit every particle with a hydrostatic pressure field across the part of
        its support that holds no water, and a particle with no water neighbour (spray, a droplet
        leaving a splash) hung in the air (docs/isph.md, "Gravity on every particle"). With the
        kernel-gradient correction (L_i = M_i^-1) the operator is exact for the linear hydrostatic P, so
        water at rest still gets v = 0 to round-off wherever L_i exists.

        A wall particle seen from i carries the value i gives it (_own_wall_pressure: the seed's virtual
        marker evaluated at i), not the wall's pressure interpolated over every particle
        that sees it: next to a free-surface row that mean fell below P_i, pushed i into the wall, and a
        cluster of pore water in a tank corner compressed itself from step to step (docs/isph.md, "A
        wall's pressure seen from each particle")."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                pi = self.p[i]
                rb_i = self.eps[i] * self.rho_w
                gp = ti.Vector.zero(float, self.dim)
                near_free = self.free[i]
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if not self._present(j):
                        continue
                    if r > 0.0:
                        gw = kernels.grad_w(rij, r, self.h, self.dim)
                        m_j, rb_j = self._mass_and_density(i, j)
                        if self.kind[j] != WALL and self.free[j] == 1:
                            near_free = 1
                        pj = self.p[j]
                        if self.kind[j] == WALL:
                            pj = self._own_wall_pressure(i, j, -rij)
                        if ti.static(self.grad_mode == GRAD_SYMMETRIC):
                            # eq 13 measured from the free surface's pressure p_s: the form is exact for a
                            # constant only on a full support, so with P itself a drop (every particle at
                            # p_s) pushed itself apart and a particle beside a wall was pushed off it
                            gp += terms.pressure_gradient_symmetric(m_j, rb_i, rb_j, pi, pj, gw)
                        else:
                            gp += terms.pressure_gradient_difference(m_j, rb_j, pi, pj, gw)
                if ti.static(self.grad_mode == GRAD_SYMMETRIC):
                    gp *= rb_i
                if ti.static(self.grad_mode == GRAD_CORRECTED):
                    if ti.static(self.porous and not self.ground_correction):
                        # inside saturated ground (eps_i < 1, no free-surface particle within the support) of
                        # weak drag the plain eq 12: on the sparse, disordered pore water M_i's smallest
                        # eigenvalue falls to 0.2-0.3 and L_i amplifies the gradient beyond what the PPE's
                        # Laplacian (eq 24) assumes, so the projection overshoots, and where the drag does not
                        # damp the overshoot within the step (D < DRAG_CORRECTED) it grew from step to step
                        # (the permeameter's plug pressure alternated, the column bounced). Next to a surface
                        # the support is one-sided and L_i is kept: it carries the front of water entering
                        # dry ground (without it the free fall arrived 18 % late); in fine sand (D ~ 2000) it
                        # keeps water at rest hydrostatic (plain eq 12 on the pore lattice: +2 %)
                        if self.eps[i] >= 1.0 or near_free == 1 or self.drag[i] >= DRAG_CORRECTED:
                            gp = self.L[i] @ gp
                    else:
                        gp = self.L[i] @ gp
                self.v[i] = self.vstar[i] - self.kcoef[i] * gp

    @ti.kernel
    def _k_collision(self):
        """Near-contact collisions. Water pairs closer than r_coll that approach lose (1 + e)/2 of their
        relative normal velocity (equal masses). At walls the kinematic condition v . n >= 0 is enforced
        on particles that are, or would be after this step's advection, closer to the wall surface than
        r_coll / 2 (a particle at rest sits dx / 2 from it): the velocity into the wall (relative to it,
        when it moves) is reversed with restitution e. Testing the end of the step makes the condition
        independent of dt: in porous ground water advects at v / eps, and a particle could cross the zone
        and the wall's first layer within one step. The wall surface lies dx / 2 beyond the first wall
        layer along the wall particle's normal. The condition is taken against every wall particle in the
        support, one after the other (a second of the same face then finds v . n >= 0 and does nothing),
        so that in a corner both faces hold. Taken against the nearest wall particle only, a particle in a
        tank's corner column, as near to both faces, took the face the round-off of its distances chose:
        in the coarse free fall a perturbation of 1e-12 dx of the cube's particles grew to 1e-2 dx within
        one step as it entered the ground (0.035 s), and the CPU and CUDA runs parted there (arrival
        0.366 against 0.399 s); with every face, 1e-10 dx at 0.1 s."""
        self.collisions[None] = 0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                xi = self.x[i]
                vi = self.v[i]
                dv = ti.Vector.zero(float, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if self.kind[j] != WALL and r < self.r_coll and r > 0.0:
                        dvj, hit = terms.collision_impulse(vi, self.v[j], -rij / r, self.restitution)
                        dv += dvj
                        if hit == 1:
                            ti.atomic_add(self.collisions[None], 1)
                vnew = vi + dv
                for k in range(self.grid.nbr_count[i]):
                    j, rij, r = self._pair(i, k, xi)
                    if self.kind[j] == WALL:
                        n_wall = self.normal[j]
                        d_wall = rij.dot(n_wall) - 0.5 * self.dx
                        vn = (vnew - self.v[j]).dot(n_wall)
                        # the zone is tested where the particle ends this step's advection (x += dt v / eps
                        # with pore advection): a particle fast enough to cross it within one step is caught
                        un = vn
                        if ti.static(self.pore_advection):
                            un = vn / self.eps[i]
                        if d_wall + self.dt[None] * ti.min(un, 0.0) < 0.5 * self.r_coll and vn < 0.0:
                            vnew -= (1.0 + self.restitution) * vn * n_wall
                            ti.atomic_add(self.collisions[None], 1)
                self.vtmp[i] = vnew
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                self.v[i] = self.vtmp[i]

    @ti.func
    def _advection_velocity(self, i):
        """u = v / eps (pore advection) or v (Darcy)."""
        u = self.v[i]
        if ti.static(self.pore_advection):
            u = u / self.eps[i]
        return u

    @ti.kernel
    def _k_advect(self, frac: float):
        """x += dt u, u = v / eps (pore) or v (Darcy); plus the shifting displacement of `_shift` over the
        fraction frac of the step (the first of `shift_substeps`, with grad C of the step's start)."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                dt = self.dt[None]
                dr = dt * self._advection_velocity(i)
                if ti.static(self.shifting):
                    dr += self._shift(i, frac)
                self.x[i] += dr
                if ti.static(self.periodic):
                    self.x[i] = operators.wrap(self.x[i], self.period)

    @ti.kernel
    def _k_diagnostics(self) -> ti.types.vector(8, ti.f64):
        """Kinetic energy, max speed, water volume, count of non-finite values, first bad particle id,
        number of free-surface particles, number of isolated water particles, lowest water pressure;
        summed in the run's precision and returned in f64. (A return type of `float` would take the
        precision Taichi had when this module was imported: f32 where that came before `ti.init`, as in
        a process that imports the solvers first, so an f64 run's diagnostics were cut to f32 there.)"""
        n_isolated = 0.0
        pmin = 1.0e30  # no water: reported as 0
        ke = 0.0
        vmax = 0.0
        vol = 0.0
        bad = 0.0
        first_bad = 2.0e9
        nfree = 0.0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.solve_mask[i] == 1:
                u = self.v[i] / self.eps[i]
                s2 = u.dot(u)
                ke += 0.5 * self.mass * s2
                ti.atomic_max(vmax, ti.sqrt(s2))
                ti.atomic_min(pmin, self.p[i])
                if self.isolated[i] == 1:
                    n_isolated += 1.0
                if self.free[i] == 1:
                    vol += self.mass / self.rho_w
                    nfree += 1.0
                else:
                    vol += self.mass * self.eps[i] / self.rho_n[i]
                val = s2 + self.p[i] + self.x[i].sum()
                if ti.math.isnan(val) or ti.math.isinf(val):
                    bad += 1.0
                    ti.atomic_min(first_bad, float(self.ids[i]))
        return ti.Vector([ke, vmax, vol, bad, first_bad, nfree, n_isolated, pmin])

    # ------------------------------------------------------------------ step
    def _widen_ppe(self, exc: EllOverflowError, dt: float) -> None:
        """A PPE row needed more slots than the ELL matrix has (the water crowded: compression, impact):
        continue with a matrix 1.25 x wider than that row needs (its kernels compile once), the warm start
        kept, and say so. Past the neighbour-list capacity no row can grow, so that stays an error."""
        width = min(int(math.ceil(1.25 * exc.needed)), self.max_nb)
        if width < exc.needed:
            raise InstabilityError(
                f"step {self.step_count + 1}, t = {self.time + dt:.6g} s: a PPE row has {exc.needed} "
                f"off-diagonal entries, beyond the neighbour-list capacity {self.max_nb}",
                step=self.step_count + 1, time=self.time + dt, quantity="PPE row width", family="solver")
        log.warning("step %d, t = %.6g s: a PPE row has %d off-diagonal entries, the ELL matrix held %d; "
                    "widened to %d (set isph.ppe.width to start there)", self.step_count + 1, self.time + dt,
                    exc.needed, exc.capacity, width)
        self.ppe = self.ppe.with_width(width)
        self.b = self.ppe.b
        self.psol = self.ppe.x
        self.ppe_widenings += 1

    def neighbour_search(self):
        self._sort_and_reorder()
        self._k_rows()
        try:
            self.grid.build_neighbour_lists(self.x, self.solve_mask, self.n, self.re, self.ids)
        except NeighbourOverflowError as exc:
            raise guard.neighbour_overflow_error(self.step_count, self.time, exc) from None

    def update_porosity(self):
        """eps and D50 of every water particle from the soil markers (eq 32); nothing without soil."""
        if self.porous:
            self.markers.porosity(self.x, self.solve_mask, self.n, self.eps, self.d50, self.ground_reach)

    def step(self, dt: float) -> dict:
        t0 = _time.perf_counter()
        if self.motion.any:
            self.motion.set_step(self.time, self.time + dt)
            self.motion.assign(self.v, self.n)
        self.neighbour_search()
        t0 = self._tick("neighbours", t0)
        self.update_porosity()
        t0 = self._tick("porosity", t0)
        self._k_wet()
        self._k_density()
        if self.pore_density:
            self._k_pore_density()
        if self.ground_cone:
            self._k_surface_cone()
        if self.porous:
            self._closed_bodies()
        t0 = self._tick("density", t0)
        if self.turbulence:
            self._k_eddy_viscosity()
        self.dt[None] = dt
        self._k_predictor()
        t0 = self._tick("predictor", t0)
        if self.ppe_ell:
            self._k_gather_pressure(self.psol)  # warm start: the solver's x is the last pressure in this step's rows
            self._assemble_ppe()
            t0 = self._tick("ppe_assembly", t0)
            try:
                sol, iters, res, ok = self._solve_ppe(None, None)
            except EllOverflowError as exc:
                self._widen_ppe(exc, dt)
                self._assemble_ppe()
                sol, iters, res, ok = self._solve_ppe(None, None)
        else:
            b = self._assemble_ppe()
            self._k_gather_pressure(self.psol)
            x0 = self.psol.to_numpy()[: self.n_water]
            t0 = self._tick("ppe_assembly", t0)
            sol, iters, res, ok = self._solve_ppe(b, x0)
        if self.ground_tension:
            iters, res, ok, sol = self._solve_tension(iters, res, ok, sol)
        t0 = self._tick("ppe_solve", t0)
        if not ok:
            guard.solver_failure(self.step_count + 1, self.time + dt, iters, res, self.ppe.tolerance,
                                 self.cfg.isph.ppe.on_failure)
        self._k_scatter_pressure(self.psol)
        if self.ground_cone:
            self._k_remember_air()
        self._k_water_gradient()
        self._k_corrector()
        collisions = 0
        if self.collision:
            self._k_collision()
            collisions = int(self.collisions[None])
        nsub = 1
        if self.shifting and self.porous:
            nsub = min(max(1, math.ceil(self._k_shift_number() / SHIFT_NUMBER_MAX)), SHIFT_SUBSTEPS_MAX)
        self._k_advect(1.0 / nsub)
        for _ in range(nsub - 1):
            self._k_grad_c()
            self._k_shift(1.0 / nsub)
        if self.motion.any:
            self.motion.advance(self.x, self.n)
        t0 = self._tick("corrector", t0)
        self.step_count += 1
        self.time += dt
        d = self._k_diagnostics().to_numpy()
        self._tick("diagnostics", t0)
        self.last = {"kinetic_energy": float(d[0]), "max_speed": float(d[1]), "water_volume": float(d[2]),
                     "cg_iterations": iters, "cg_residual": res, "free_surface": int(d[5]), "isolated": int(d[6]),
                     "closed_bodies": int(self.closed_bodies[None]),
                     "collisions": collisions, "shift_substeps": nsub, "pressure_min": _lowest(d[7])}
        if d[3] > 0:
            raise guard.non_finite_error(self.step_count, self.time, int(d[3]), int(d[4]),
                                         "position, velocity or pressure")
        return self.last

    def initial_diagnostics(self) -> dict:
        """Neighbour search and density at t = 0 (for the first frame and the reference volume)."""
        self.neighbour_search()
        self.update_porosity()
        self._k_wet()
        self._k_density()
        if self.ground_cone:
            self.air_last.fill(1)
            self._k_surface_cone()
            self._k_remember_air()
        if self.pore_density:
            self._k_pore_density()
            # each particle's block packing, in the order the neighbour search left the particles
            self.packing.from_numpy(self._scene_packing[self.ids.to_numpy()].astype(self.np_fp))
        if self.porous:
            self._k_rest_fill()
        d = self._k_diagnostics().to_numpy()
        self.last = {"kinetic_energy": float(d[0]), "max_speed": float(d[1]), "water_volume": float(d[2]),
                     "cg_iterations": 0, "cg_residual": 0.0, "free_surface": int(d[5]), "isolated": int(d[6]),
                     "closed_bodies": int(self.closed_bodies[None]), "collisions": 0, "shift_substeps": 0,
                     "pressure_min": _lowest(d[7])}
        return self.last

    # ------------------------------------------------------------------ output
    def fields_by_id(self) -> dict:
        """Per-particle arrays in id order (SPEC 8 frame fields). The wall particles' pressure is the kernel
        mean of what the water around gives them (walls.WallPressure), computed here: the step itself takes
        each water particle's own value at a wall (_own_wall_pressure)."""
        n = self.n
        self.wall_pressure.update()
        order = self._id_order()
        kind = self.kind.to_numpy()[:n][order]
        rho = self.rho_n.to_numpy()[:n][order]
        rho = np.where(kind == WATER, rho, self.rho_w)
        out = {
            "position": self.x.to_numpy()[:n][order],
            "velocity": self.v.to_numpy()[:n][order],
            "pressure": self.p.to_numpy()[:n][order],
            "density": rho,
            "active": self.active.to_numpy()[:n][order].astype(bool),
            # the PPE's Dirichlet rows (eq 34) and the water particles with no water neighbour
            "free_surface": (self.free.to_numpy()[:n][order] == 1) & (kind == WATER),
            "isolated": (self.isolated.to_numpy()[:n][order] == 1) & (kind == WATER),
        }
        out["free_surface"] &= out["active"]
        out["isolated"] &= out["active"]
        if self.porous:
            out["porosity"] = np.where(kind == WATER, self.eps.to_numpy()[:n][order], 1.0)
        return out

    # ------------------------------------------------------------------ checkpoints
    #: fields that carry over from one step to the next (all else is recomputed by each step); the
    #: pressure is the PPE's warm start. Per-particle state added later belongs in this tuple.
    state_fields = ("x", "v", "normal", "p", "eps", "kind", "ids", "active", "rho_n", "d50", "rest_fill",
                    "rest_fill_pore", "wall_body", "wall_origin", "air_last")
    state_scalars = ("step_count", "time", "removed_total")

    def state(self) -> dict:
        """Full state for a checkpoint, {name: numpy array or scalar} (sph/state.py)."""
        from ..sph.state import snapshot

        return snapshot(self, self.state_fields, self.state_scalars)

    def load_state(self, state: dict) -> None:
        """Continue from a `state()` of a solver built from the same config."""
        from ..sph.state import restore

        if "air_last" not in state:
            # saved before the cone test looked for air: every surface is open to it, as at t = 0
            state = {**state, "air_last": np.ones(self.n, np.int32)}
        if "rest_fill_pore" not in state:
            # saved before the pore lattice's support: its rest state is the pore lattice's
            state = {**state, "rest_fill_pore": np.ones(self.n)}
        restore(self, state, self.state_fields, self.state_scalars)


def _lowest(pmin: float) -> float:
    """The diagnostics' lowest water pressure (Pa); 0 where there was no water (the kernel's start value)."""
    return float(pmin) if pmin < 1.0e29 else 0.0


def ppe_width(cfg) -> int:
    """ELL row width of the PPE: `isph.ppe.width`, or 1.5 x the kernel's lattice neighbour count (20 in
    2D, 56 in 3D), at most the neighbour-list capacity. Rows are strided by the width, so it costs
    memory traffic; water in a PPE stays near the lattice spacing (incompressible), and the solve
    names `isph.ppe.width` when a row needs more."""
    if cfg.isph.ppe.width is not None:
        return int(cfg.isph.ppe.width)
    lattice = kernels.lattice_sums(cfg.dim)["neighbours"]
    return min(int(math.ceil(1.5 * lattice)), cfg.max_neighbours())


def check_sparse_cg_backend(ppe_cfg, cpu: bool) -> None:
    """isph.ppe.type sparse_cg off the CPU: Taichi 1.7.4's sparse matrices are f32 there and its SparseCG
    has no preconditioner, so a tolerance below what f32 CG reaches is refused before the run starts
    (InputError naming the key) rather than failing at the first solve."""
    from ..config.schema import F32_PPE_TOLERANCE

    if not cpu and ppe_cfg.tolerance < F32_PPE_TOLERANCE:
        raise InputError(f"isph.ppe.type: sparse_cg off the CPU solves in f32 without a preconditioner and cannot "
                         f"reach isph.ppe.tolerance {ppe_cfg.tolerance:g} (below {F32_PPE_TOLERANCE:g}); "
                         f"use ell_pcg or mg_pcg on a GPU")


def ppe_precision(ppe_cfg, runtime_fp):
    """Floats of the ELL PPE solve: the key, or f64 when the tolerance is below what f32 CG reaches."""
    from ..config.schema import F32_PPE_TOLERANCE

    if ppe_cfg.precision == "f64" or (ppe_cfg.precision == "auto" and ppe_cfg.tolerance < F32_PPE_TOLERANCE):
        return ti.f64
    if ppe_cfg.precision == "f32":
        return ti.f32
    return runtime_fp


def _spline(q: float) -> float:
    return float(kernels.w_np(q * 1.0, 1.0, 1) / kernels.sigma(1, 1.0))
