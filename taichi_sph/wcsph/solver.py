"""Weakly compressible SPH step of mode wcsph_biot (seed 002 sections 2.3-2.6): water and air; soil
particles and the Biot drag (sections 2.4-2.5) come in through soil_step.py (docs/biot.md).

State per fluid particle: position x, leap-frog velocity v (at half steps), density rho, gauge
pressure p, smoothing length h, mass m, kind (water 0, air 3). Wall particles (kind 1) are fixed
boundary particles with the Morris/Takeda virtual velocity (eq 50-51). One step of length
dt = Delta t^n starts from the accelerations a^n of the previous step (or `initial_diagnostics`):

1. kick-drift (leap-frog, eq 48): v^{n+1/2} = v^{n-1/2} + (Delta t^{n-1} + Delta t^n) / 2 a^n,
   x^{n+1} = x^n + Delta t (v^{n+1/2} + XSPH correction of eq 53); the packed views of the pair pass,
   with each fluid particle's density predicted to the end of the step, rho~ = rho^n (1 - D~ Delta t),
   D~ the divergence of eq 25 extrapolated along the line through the last two pair passes, and its
   pressure from the equations of state (eq 39-41).
2. neighbour lists, rebuilt only when some particle has moved far enough to need it (Verlet skin).
3. every `normalise_every` steps eq 27 (normalised density over the same material), its own pass.
4. pair pass at x^{n+1} with v^{n+1/2}, one walk over the neighbours of each fluid particle for both:
   the divergence D_i (eq 25 in volume form), rho^{n+1} = rho^n (1 - D_i Delta t) (eq 48),
   h^{n+1} = h^n (1 + D_i Delta t / d) (eq 52), the XSPH correction; and the accelerations a^{n+1} from
   rho~, p~: eq 34 (pressure, Morris viscosity), eq 36 (artificial viscosity), eq 54 (cohesion), gravity;
   a wall particle seen from fluid particle i has the velocity of eq 50-51, the density of i and the
   pressure of i extrapolated hydrostatically; the reductions eq 49 and the diagnostics need, written into
   a small host array (the only transfer to the host per step besides the list-rebuild test).
   The density the forces see differs from rho^{n+1} by order Delta t^3 d^3 rho / dt^3: the exact
   pair of passes (density, then forces with rho^{n+1}) needs every neighbour's new density before any
   force. With the previous pass's rate alone (rho~ = rho^n at D~ = 0, or D~ = D^{n-1/2}) the acoustic
   modes grow; with the line through the last two they decay slightly and stay stable up to a Courant
   number of 0.65 (docs/wcsph.md, "One step").

The pair pass reads each neighbour from two packed vectors (s: x, v, rho^n, m, kind[, h]; q: rho~,
p~ / rho~^2[, h~]): two contiguous loads per neighbour and step (the two passes before took three). Physics
a scene does not use is compiled out with ti.static flags (air, cohesion, artificial viscosity, XSPH,
variable h, soil, moving walls, periodic axes; their values come from taichi_sph/switches.py). Soil (eq 35,
37-45) and the Biot drag (eq 46-47) join behind flags of their own: the soil's stress update in the loop of
the pair pass, its forces and the drag in loops after it in the same kernel (soil_step.py, docs/biot.md).
"""

import logging
import math
import time as _time

import numpy as np
import taichi as ti

from .. import guard
from ..backend import check_field_room, is_f64, on_cpu
from ..contract import DT_CFL, DT_FORCE, DT_VISCOUS
from ..scene import AIR, SOIL, WALL, WATER
from ..sph import kernels, operators, walls
from ..sph.grid import NeighbourGrid, NeighbourOverflowError
from ..sph.scan import PrefixSum
from ..sph.solver_common import SolverCommon
from ..sph.wall_motion import WallMotion
from ..switches import Switches
from . import eos, terms
from .inflow import Inflow, activate
from .initial import initial_state
from .soil_step import SoilPasses

log = logging.getLogger("taichi_sph")

#: smoothing length bounds of eq 52, in units of h0 (the neighbour grid is sized for the upper one)
H_MIN, H_MAX = 0.5, 1.1
#: reductions of the fluid's pair pass (the soil's follow them in the same buffer, soil_step.NRED_SOIL)
_NRED = 9
#: length of the vector the step's kernels return their reductions in where they return them (GPUs): at
#: least _NRED plus the soil's (6 + dim + 1)
_NRET = 20
#: whether the step's kernels return their reductions (True) or write them into host arrays passed as
#: arguments (False); None: return them on GPUs. On the CPU an external host array is passed by pointer and
#: written in place, the cheapest way back; on CUDA Taichi copies such an array to a device buffer it
#: allocates, synchronises and copies it back and frees the buffer at every launch (several driver calls
#: per launch), where a kernel's return value comes back in one copy of its result buffer.
RETURN_REDUCTIONS: bool | None = None
#: largest timestep.cfl at which the one-pass step damps every acoustic mode: z = omega dt < 0.708 with the
#: fastest lattice mode omega = c G_max, G_max dx = 0.901 (2D) / 0.923 (3D), dt = cfl 1.2 dx / c
CFL_STABLE = 0.64
#: the density diffusion's gradient correction takes G_i = B_i^-1 sum_j (...) only where det B_i exceeds this
#: (B = I in a full support; a particle at a free surface has about half of it, det ~ 0.5 in 2D; a
#: fragment of water fewer neighbours still): elsewhere G_i = 0, the hydrostatic form
DD_GRAD_MIN_DET = 0.25
#: scenes with fewer fluid particles run their loops serially: thread dispatch costs ~55 us per loop.
#: Measured per step on 2 cores, serial / parallel: 500 particles 0.44 / 0.67 ms, 1200 0.77 / 0.91 ms,
#: 2450 equal; 5000 (dam break, dx 2 cm) 1.27 / 0.99 ms
SERIAL_BELOW = 2000
#: the same for scenes with soil, whose step has five parallel loops instead of two (the soil passes):
#: measured on 2 cores, f32, wall ms per step serial / parallel: levee of configs/embankment.yaml
#: (2686 moving particles) 1.78-1.91 / 1.95-2.03, its dry variant (2517) 1.20-1.26 / 1.33-1.43; at
#: dx 8.5 mm (3767) 2.39-2.42 / 2.34-2.41; at dx 7 mm (5411) 3.50-3.55 / 2.88-2.89
SERIAL_BELOW_SOIL = 4000
#: particles per chunk when the moving list of a parallel scene with soil is dealt to the threads (16, hashed
#: to threads: levee at dx 4 mm 4.98 against 6.5-7.2 ms per step in cell order; chunks of 64 resonated
#: with the scene's rows)
DEAL_CHUNK = 16


@ti.data_oriented
class WCSPHSolver(SolverCommon):
    """State and step of mode `wcsph_biot` for water and air. Built from a validated Config and a Scene."""

    #: per-step diagnostics this solver reports (run.py adds time, dt, wall_seconds, dt_limit)
    diagnostic_names = ("kinetic_energy", "max_speed", "water_volume")
    #: the step is eq 49's, from the forces of the last step (propose_dt)
    proposes_dt = True

    def __init__(self, cfg, scene):
        check_field_room()  # a clear error, not Taichi's crash, where the runtime's field trees run out
        self.cfg = cfg
        w = cfg.wcsph
        self.dim = dim = cfg.dim
        self.dx = dx = cfg.dx
        self.re = kernels.SUPPORT_FACTOR * dx
        self.h0 = 0.5 * self.re
        self.eta2 = 0.01 * self.h0**2  # Morris et al. (1997): 0.01 h^2 keeps 1 / r finite
        self.vol0 = dx**dim
        self.g_np = np.asarray(cfg.gravity_vector(), dtype=float)
        self.g_abs = float(np.linalg.norm(self.g_np))
        self.g = ti.types.vector(dim, float)(self.g_np.tolist())

        # materials: kind -> (rho0, B, gamma); sound speeds c0; viscosities nu; cohesion a / m^2
        self.p_amb = w.ambient_pressure
        self.rho_w = cfg.fluid.density
        self.c_w = cfg.sound_speed()
        self.c_av_w = cfg.viscosity_speed()  # c of eq 36 for water (wcsph.artificial_viscosity.speed)
        self.gamma_w = _exponent(w.water.gamma)
        self.b_w = eos.tait_modulus(self.rho_w, self.c_w, self.gamma_w)
        self.nu_w = cfg.fluid.viscosity
        self.rho_a = w.air.density
        self.gamma_a = _exponent(w.air.gamma)
        self.b_a = self.p_amb
        self.c_a = math.sqrt(self.gamma_a * self.b_a / self.rho_a)
        self.nu_a = w.air.viscosity
        self.coh_w = w.water.cohesion / self.rho_w**2
        self.coh_a = w.air.cohesion / self.rho_a**2
        self.materials = {WATER: (self.rho_w, self.b_w, self.gamma_w), AIR: (self.rho_a, self.b_a, self.gamma_a)}

        # ti.static switches: a scene compiles only what it uses (switches.py, also what `taichi-sph info
        # --config` reports)
        self.switches = sw = Switches.build(cfg, scene)
        # pore water at its own volume (wcsph.soil.pore_water: pore_volume): partial density, pore velocity
        self.partial = sw.pore_volume
        if cfg.timestep.cfl > CFL_STABLE:
            log.warning("timestep.cfl = %g is above %g, where the one-pass step of mode wcsph_biot stops damping "
                        "the acoustic modes (docs/wcsph.md, \"One step\"): expect them to grow", cfg.timestep.cfl,
                        CFL_STABLE)
        self.n = n = scene.n
        #: period of each axis (0.0: not periodic), for operators.rel and operators.wrap
        self.period = scene.periods()
        self.periodic = sw.periodic
        self.n_water = scene.count(WATER)
        self.n_air = scene.count(AIR)
        self.n_fluid = self.n_water + self.n_air
        self.n_wall = scene.count(WALL)
        self.has_air = sw.air
        self.cohesion_on = sw.cohesion
        self.av_alpha = w.artificial_viscosity.alpha
        self.av_beta = w.artificial_viscosity.beta
        self.av_eps = w.artificial_viscosity.eps
        self.av_on = sw.artificial_viscosity
        self.xsph_eps = w.xsph
        self.xsph_on = sw.xsph
        # density diffusion (wcsph.density_diffusion): delta h0 c0, and rho_w / c0^2 for rho^H_ji
        self.dd_on = sw.density_diffusion
        self.dd_coef = cfg.density_diffusion() * self.h0 * self.c_w
        self.dd_h = self.rho_w / self.c_w**2
        # its gradient correction: G of the last pair pass, packed into s for the neighbours
        self.dd_grad = sw.density_diffusion_gradient
        self.variable_h = sw.variable_h
        self.normalised = sw.normalised_density
        self.normalise_every = w.normalise_every
        self.no_slip = sw.no_slip
        self.beta_max = w.beta_max
        self.mass = self.rho_w * self.vol0  # reference water particle mass (run file attribute)
        # largest kinematic viscosity a particle feels (Morris pair coefficient (mu_i + mu_j) / (2 rho_i))
        nus = [self.nu_w] if self.n_water else []
        if self.has_air:
            nus += [self.nu_a, (self.rho_a * self.nu_a + self.rho_w * self.nu_w) / (2.0 * self.rho_a)]
        self.nu_max = max(nus) if nus else 0.0

        self.n_soil = scene.count(SOIL)
        self.has_soil = sw.soil
        self.coupled = sw.soil_water  # pore pressure and drag
        self.soil_air = sw.soil_air  # drag between soil and air
        self.drag_on = self.coupled or self.soil_air
        if self.drag_on:  # the drag's momentum check (soil_step.py)
            self.diagnostic_names = (*self.diagnostic_names, "drag_sum", "drag_max")

        self.h_lo = H_MIN * self.h0 if self.variable_h else self.h0
        self.h_hi = H_MAX * self.h0 if self.variable_h else self.h0
        self.skin = w.neighbour_skin * self.re
        self.cell = 2.0 * self.h_hi + self.skin
        self.max_nb = cfg.max_neighbours()
        if self.has_soil and cfg.neighbours.max is None:  # soil overlaps the fluid: twice the neighbours
            self.max_nb *= 2

        # packed neighbour views, written by the kick-drift. s: x (dim), v (dim), rho^n, m, kind[, h^n];
        # q: the predicted rho~, p~ / rho~^2[, h~] the pair pass takes its forces from. Each pass writes
        # only fields that no particle reads in that pass, so every step is two loops.
        self.S_V = dim
        self.S_RHO = 2 * dim
        self.S_M = 2 * dim + 1
        self.S_KIND = 2 * dim + 2
        self.S_H = 2 * dim + 3
        self.ns = 2 * dim + 3 + (1 if self.variable_h else 0)
        self.S_G = self.ns  # the density diffusion's gradient G (dim), with its gradient correction only
        self.ns += dim if self.dd_grad else 0
        self.Q_RHO, self.Q_PR, self.Q_H = 0, 1, 2
        self.nq = 3 if self.variable_h else 2
        # small scenes run their loops serially on the CPU: a parallel loop costs ~50 us of thread dispatch
        # there (never on a GPU, where a serial loop runs on one slow thread)
        self.serial = on_cpu() and (
            self.n_fluid + self.n_soil < (SERIAL_BELOW_SOIL if self.n_soil else SERIAL_BELOW))

        vec = ti.Vector.field
        self.s = vec(self.ns, float, n)
        self.q = vec(self.nq, float, n)
        # positions, density and smoothing length are f64 at either precision: each step adds to them an
        # increment far below their f32 resolution (a seeping particle moves ~1e-8 m per step at x ~ 1 m,
        # where f32 resolves 1.2e-7 m; the density of stiff pore water changes by ~1e-6 kg/m^3 per step
        # against 6e-5), which f32 would round away (docs/performance_wcsph.md, "Precision"). The pair
        # pass reads them through the packed views in the run's precision.
        self.x = vec(dim, ti.f64, n)
        self.v = vec(dim, float, n)  # leap-frog velocity v^{n+1/2}
        self.a = vec(dim, float, n)
        self.xs = vec(dim, float, n)  # XSPH correction eq 53
        self.rate = vec(2, float, n)  # divergence of eq 25, last two pair passes: D^{n-1/2}, D^{n-3/2}
        self.normal = vec(dim, float, n)
        self.x0 = vec(dim, ti.f64, n)  # positions at the last neighbour-list build
        self.rho = ti.field(ti.f64, n)
        self.p = ti.field(float, n)
        self.h = ti.field(ti.f64, n)
        self.m = ti.field(float, n)
        self.wdepth = ti.field(float, n)
        self.kind = ti.field(ti.i32, n)
        self.ids = ti.field(ti.i32, n)
        self.active = ti.field(ti.i32, n)
        self.fmask = ti.field(ti.i32, n)
        # the particles the pair pass walks (fmask >= 1: fluid and soil), in index (cell) order, rebuilt with
        # the lists (_k_moving_list): Taichi's CPU backend splits a parallel loop's range into one contiguous
        # block per thread (whatever block_dim says), so a loop over all n particles gave one thread the water
        # and the other the wall particles (3D slice at 200k water: 1.0 CPU s per wall s on two threads)
        self.moving_ids = ti.field(ti.i32, n)
        self.n_moving = ti.field(ti.i32, ())
        # with soil and parallel loops, the list is dealt to the threads in chunks of DEAL_CHUNK particles
        # (`_k_moving_list`, `deal_threads`): each pass works on another part of the scene (the fluid pass on
        # all of it, the force pass on the soil, the drag passes on the water in the soil), and a contiguous
        # block per thread gave one thread the levee and the other the river (levee at dx 4 mm, 16.8k
        # moving particles: 1.25 CPU s per wall s, 1.32x the serial speed; dealt 1.77,
        # docs/performance_wcsph.md)
        self.deal = deal_threads(self.has_soil, self.serial)
        self.moving_tmp = ti.field(ti.i32, n if self.deal > 1 else 1)
        self._moving_scan = PrefixSum(n)
        # on GPUs the passes over moving_ids launch all n entries, the particles that do not move listed after
        # the moving ones and turned away by their fmask: a loop whose count is read from a field runs on
        # Taichi's saturating grid (540,672 threads on an H100) whatever the count, each thread ending with
        # its own atomic per reduction, and the pair pass cost 6.6-6.9 ms of device time a step so at 10k
        # and at 200k particles; 1.1 and 2.8 ms a step now (docs/performance.md, GPU, "Third round")
        self.exact_grid = self._moving_scan.blocked
        self.moving_flag = ti.field(ti.i32, n if self._moving_scan.blocked else 1)
        self.moving_start = ti.field(ti.i32, n + 1 if self._moving_scan.blocked else 1)
        self.group = ti.field(ti.i32, n if self.has_soil else 1)  # the list order of a neighbour (_k_mask)
        self.particle_fields = [self.x, self.v, self.a, self.xs, self.rate, self.normal, self.rho, self.p,
                                self.h, self.m, self.wdepth, self.kind, self.ids, self.active]
        # renormalised gradient of rho - rho^H at water particles, from the last pair pass (density diffusion's
        # gradient correction)
        self.grad_rho = vec(dim, float, n if self.dd_grad else 1)
        if self.dd_grad:
            self.particle_fields.append(self.grad_rho)
            self.state_fields = (*type(self).state_fields, "grad_rho")
        # soil state and passes (soil_step.py); its fields are one element long in a scene without soil
        self.soil = SoilPasses(self, cfg, scene)
        self.particle_fields += self.soil.particle_fields
        self.run_attrs = dict(self.soil.run_attrs)

        init = initial_state(cfg, scene, self.materials)
        self.np_fp = np.float64 if is_f64() else np.float32
        f = self.np_fp
        self.x.from_numpy(scene.position.astype(np.float64))
        self.normal.from_numpy(scene.normal.astype(f))
        self.kind.from_numpy(scene.kind.astype(np.int32))
        self.ids.from_numpy(scene.ids)
        self.active.fill(1)
        self.inflow = None  # river inflow: reserve water released row by row (inflow.py)
        if scene.inflow_rows:
            self.inflow = Inflow(cfg, scene.inflow_rows)
            if self.inflow.controlled:  # a river held at a level: its gates and volumes go into checkpoints
                self.state_scalars = (*type(self).state_scalars, "inflow_state")
            active = np.ones(n, np.int32)
            active[self.inflow.reserve_ids()] = 0
            self.active.from_numpy(active)
        self.v.from_numpy(init["velocity"].astype(f))
        self.rho.from_numpy(init["density"].astype(np.float64))
        self.p.from_numpy(init["pressure"].astype(f))
        self.m.from_numpy(init["mass"].astype(f))
        self.wdepth.from_numpy(init["wall_depth"].astype(f))
        self.h.fill(self.h0)
        self.a.fill(0.0)
        self.xs.fill(0.0)
        self.rate.fill(0.0)
        # obstacles with a prescribed motion (sph/wall_motion.py), moved by the kick-drift; their wall
        # particles' v is the wall velocity of eq 50-51
        self.motion = WallMotion(scene, dim, self.period)
        self.wall_body = self.motion.body
        self.wall_origin = self.motion.origin
        self.moving = sw.moving_walls
        self.particle_fields += self.motion.fields()
        self.initial_density = init["density"]
        if self.has_soil:
            self.soil.sig.from_numpy(init["stress"].astype(f))
            if "plastic_strain" in init:  # two-stage run (stage.py)
                self.soil.eps_p.from_numpy(init["plastic_strain"].astype(f))

        # with soil, each list holds the soil neighbours first, then the walls, then the fluid (`group`, the
        # grid's grouped build): the fluid's pair pass walks walls and fluid, the soil's stress soil and walls, the
        # drag passes the other set, each its own range of the list
        self.grid = NeighbourGrid(n, dim, scene.lo, scene.hi, self.cell, self.max_nb, period=self.period,
                                  grouped=self.has_soil, serial=self.serial)
        self.wall_pressure = walls.WallPressure(self, n)
        self.r_list = 0.0  # list radius at the last build
        self.hmax = self.h0
        self.rebuilds = 0
        #: particle arrays are put into cell order at every `reorder_every`-th list build (1: at every build;
        #: measured in docs/performance_wcsph.md, "Cell order"); the builds in between walk the cells
        #: through the sort's permutation
        self.reorder_every = 1
        self.searches = 0
        self.dt_prev = 0.0
        self.dt_prev2 = 0.0
        self.rates_known = 0  # pair passes behind the divergences in `rate` (at most 2)
        self.removed_total = 0
        self.step_count = 0
        self.time = 0.0
        self.timers = {k: 0.0 for k in ("update", "neighbours", "pairs")}
        self.red = np.zeros(_NRED)
        # reductions of the kick and of the pair pass (with the soil's passes), written by the kernels
        # straight into these host arrays (external-array arguments: no read-back launch, no per-element
        # reads, which cost ~2.5 us each)
        self.red_kick = np.zeros(2, self.np_fp)
        self.n_red = _NRED + (self.soil.nred if self.has_soil else 0)
        self.red_pairs = np.zeros(self.n_red, self.np_fp)
        self.last = {}
        # the two kernels of every step, bound once: reading a kernel off a data-oriented object makes a new
        # bound method at each access (the levee of 1489 moving particles: 2 % less CPU per step, 4 rounds)
        self.returns_reductions = (not on_cpu()) if RETURN_REDUCTIONS is None else bool(RETURN_REDUCTIONS)
        assert self.n_red <= _NRET
        self._step_kernels = ((self._k_kick_drift_ret, self._k_pairs_ret) if self.returns_reductions
                              else (self._k_kick_drift, self._k_pairs))

    # ------------------------------------------------------------------ materials
    @ti.func
    def _is_air(self, k):
        out = False
        if ti.static(self.has_air):
            out = k == AIR
        return out

    @ti.func
    def _eos_pressure(self, k, rho):
        p = eos.pressure(rho, self.rho_w, self.b_w, self.gamma_w)
        if self._is_air(k):
            p = eos.pressure(rho, self.rho_a, self.b_a, self.gamma_a)
        return p

    @ti.func
    def _sound_speed(self, k, rho):
        c = eos.sound_speed(rho, self.rho_w, self.b_w, self.gamma_w)
        if self._is_air(k):
            c = eos.sound_speed(rho, self.rho_a, self.b_a, self.gamma_a)
        return c

    @ti.func
    def _nu(self, k):
        nu = self.nu_w
        if self._is_air(k):
            nu = self.nu_a
        return nu

    @ti.func
    def _c_av(self, k):
        """c_ij of the artificial viscosity eq 36 for material k (schema.viscosity_speed for water)."""
        c = self.c_av_w
        if self._is_air(k):
            c = self.c_a
        return c

    @ti.func
    def _cohesion(self, k):
        coh = self.coh_w
        if self._is_air(k):
            coh = self.coh_a
        return coh

    # ------------------------------------------------------------------ packed view
    @ti.func
    def xf(self, i):
        """Position of particle i in the run's precision (the field is f64)."""
        return ti.cast(self.x[i], float)

    @ti.func
    def rhof(self, i):
        """Density of particle i in the run's precision (the field is f64)."""
        return ti.cast(self.rho[i], float)

    @ti.func
    def nbr_walls(self, i):
        """Where the wall neighbours start in i's list (soil first, then walls, then fluid; 0 without soil)."""
        k = 0
        if ti.static(self.has_soil):
            k = self.grid.nbr_split[i][0]
        return k

    @ti.func
    def nbr_fluid(self, i):
        """Where the fluid neighbours (water, air) start in i's list (after the soil and the walls)."""
        k = 0
        if ti.static(self.has_soil):
            k = self.grid.nbr_split[i][1]
        return k

    @ti.func
    def _pos(self, sj):
        return ti.Vector([sj[d] for d in ti.static(range(self.dim))])

    @ti.func
    def _vel(self, sj):
        return ti.Vector([sj[self.S_V + d] for d in ti.static(range(self.dim))])

    @ti.func
    def _h_pair(self, hi, sj):
        """h_ij = (h_i + h_j) / 2 (eq 7), or the constant h0."""
        hij = self.h0
        if ti.static(self.variable_h):
            hij = 0.5 * (hi + sj[self.S_H])
        return hij

    @ti.func
    def _pack_s(self, i):
        """View s of particle i: x^{n+1}, v^{n+1/2}, rho^n, m, kind[, h^n]."""
        for d in ti.static(range(self.dim)):
            self.s[i][d] = ti.cast(self.x[i][d], float)
            self.s[i][self.S_V + d] = self.v[i][d]
        self.s[i][self.S_RHO] = ti.cast(self.rho[i], float)
        self.s[i][self.S_M] = self.m[i]
        self.s[i][self.S_KIND] = ti.cast(self.kind[i], float)
        if ti.static(self.variable_h):
            self.s[i][self.S_H] = ti.cast(self.h[i], float)
        if ti.static(self.dd_grad):
            for d in ti.static(range(self.dim)):
                self.s[i][self.S_G + d] = self.grad_rho[i][d]

    @ti.func
    def _pack_q(self, i, dt, w1, w2):
        """View q of particle i: the state the pair pass takes its pressures from. For a fluid particle the
        density predicted to the end of the step, rho~ = rho^n (1 - D~ dt) with the divergence extrapolated
        from the last two pair passes, D~ = w1 D^{n-1/2} + w2 D^{n-3/2} (docs/wcsph.md, "One step"), its
        pressure p~ / rho~^2 by the equations of state and h~ by eq 52; rho^n and p^n with dt = 0. Computed
        in f64 (rho and h are f64) and stored in the run's precision."""
        rho = self.rho[i]
        pr = self.p[i] / (rho * rho)
        h = self.h[i]
        if self.fmask[i] == 1 and dt > 0.0:
            dd = ti.cast((w1 * self.rate[i][0] + w2 * self.rate[i][1]) * dt, ti.f64)
            rho = rho * (1.0 - dd)
            pr = self._eos_pressure(self.kind[i], rho) / (rho * rho)
            if ti.static(self.variable_h):
                h = ti.min(ti.max(h * (1.0 + dd / self.dim), self.h_lo), self.h_hi)
        self.q[i][self.Q_RHO] = ti.cast(rho, float)
        self.q[i][self.Q_PR] = ti.cast(pr, float)
        if ti.static(self.variable_h):
            self.q[i][self.Q_H] = ti.cast(h, float)

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _k_mask(self):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.fmask[i] = 1 if (self.active[i] == 1 and self.kind[i] != WALL) else 0
            if ti.static(self.has_soil):
                if self.active[i] == 1 and self.kind[i] == SOIL:
                    self.fmask[i] = 2  # soil: moved by kick-drift, its own passes (soil_step.py)
                # neighbour-list order: soil, walls, fluid (water and air)
                self.group[i] = 0 if self.kind[i] == SOIL else (1 if self.kind[i] == WALL else 2)

    @ti.kernel
    def _k_moving_list(self):
        """The indices of the moving particles (fmask >= 1), in index order, into moving_ids[:n_moving]; with
        the blocked prefix sum (GPUs) the other particles follow them in index order (exact_grid); with
        `deal` threads, the chunks of DEAL_CHUNK of that order dealt to the threads by a hash of the chunk's
        index, thread t's chunks forming the t-th block of the list (about the block Taichi's CPU backend
        gives that thread)."""
        if ti.static(self._moving_scan.blocked):
            # GPUs: a blocked prefix sum of the flags (sph/scan.py) instead of one thread's running count
            for i in range(self.n):
                self.moving_flag[i] = 1 if self.fmask[i] >= 1 else 0
            self._moving_scan.exclusive(self.moving_flag, self.moving_start, self.n)
            for i in range(self.n):
                if self.fmask[i] >= 1:
                    self.moving_ids[self.moving_start[i]] = i
                else:  # the particles that do not move after them (exact_grid's loops run over all n)
                    self.moving_ids[self.moving_start[self.n] + i - self.moving_start[i]] = i
            self.n_moving[None] = self.moving_start[self.n]
        else:
            self.n_moving[None] = 0
            ti.loop_config(serialize=True)
            for i in range(self.n):
                if self.fmask[i] >= 1:
                    k = self.n_moving[None]
                    self.moving_ids[k] = i
                    self.n_moving[None] = k + 1
        if ti.static(self.deal > 1):
            nm = self.n_moving[None]
            nch = (nm + DEAL_CHUNK - 1) // DEAL_CHUNK
            ti.loop_config(serialize=True)
            for k in range(nm):
                self.moving_tmp[k] = self.moving_ids[k]
            pos = 0
            ti.loop_config(serialize=True)
            for t in range(self.deal):
                for c in range(nch):
                    # the thread of chunk c by a multiplicative hash, not c % deal: round robin resonated
                    # with the scene's row structure (levee at dx 5 mm: one thread still got most work)
                    hc = (ti.cast(c, ti.u32) * ti.u32(2654435761)) >> ti.u32(16)
                    if ti.cast(hc % ti.u32(self.deal), ti.i32) == t:
                        for k in range(c * DEAL_CHUNK, ti.min(nm, (c + 1) * DEAL_CHUNK)):
                            self.moving_ids[pos] = self.moving_tmp[k]
                            pos += 1

    @ti.kernel
    def _k_after_build(self, dt: float, w1: float, w2: float):
        """After a list build: positions at build time and the packed views."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.x0[i] = self.x[i]
            self._pack_s(i)
            self._pack_q(i, dt, w1, w2)

    @ti.kernel
    def _k_kick_drift(self, dt: float, dt_prev: float, w1: float, w2: float, out: ti.types.ndarray()):
        """`_kick_drift`, its two reductions written into `out` (a host array: the CPU's way)."""
        red = self._kick_drift(dt, dt_prev, w1, w2)
        out[0] = red[0]
        out[1] = red[1]

    @ti.kernel
    def _k_kick_drift_ret(self, dt: float, dt_prev: float, w1: float, w2: float) -> ti.types.vector(2, ti.f64):
        """`_kick_drift`, its two reductions returned (GPUs: RETURN_REDUCTIONS)."""
        red = self._kick_drift(dt, dt_prev, w1, w2)
        return ti.Vector([ti.cast(red[0], ti.f64), ti.cast(red[1], ti.f64)])

    @ti.func
    def _kick_drift(self, dt, dt_prev, w1, w2):
        """Leap-frog (eq 48): kick with a^n, drift with v^{n+1/2} plus the XSPH correction (eq 53); then the
        packed views of the pair pass (`_pack_s`, `_pack_q`). Returns the largest squared displacement
        since the last list build and the largest h the pair pass will use."""
        d2max = 0.0
        hmax = 0.0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.fmask[i] >= 1:
                ai = self.a[i]
                if ti.static(self.has_soil):
                    ai += self.soil.adrag[i]
                vh = self.v[i] + 0.5 * (dt_prev + dt) * ai
                self.v[i] = vh
                xn = self.x[i] + dt * vh
                if ti.static(self.xsph_on):
                    xn += dt * self.xs[i]
                if ti.static(self.periodic):
                    xn = operators.wrap(xn, self.period)
                self.x[i] = xn
                self._pack_s(i)
                self._pack_q(i, dt, w1, w2)
                dd = operators.rel(xn, self.x0[i], self.period)
                ti.atomic_max(d2max, ti.cast(dd.dot(dd), float))
                if ti.static(self.variable_h):
                    ti.atomic_max(hmax, self.q[i][self.Q_H])
            if ti.static(self.moving):  # noqa: SIM102 (compile-time if)
                if self.wall_body[i] >= 0:  # a moving obstacle's wall particle: its velocity over this step
                    vb = self.motion.vel[self.wall_body[i]]
                    self.v[i] = vb
                    xn = self.motion.position(i)
                    self.x[i] = xn
                    for d in ti.static(range(self.dim)):
                        self.s[i][d] = ti.cast(xn[d], float)
                        self.s[i][self.S_V + d] = vb[d]
                    dd = operators.rel(xn, self.x0[i], self.period)
                    ti.atomic_max(d2max, ti.cast(dd.dot(dd), float))
        return ti.Vector([d2max, hmax])

    @ti.kernel
    def _k_normalise(self, dt: float, w1: float, w2: float):
        """Eq 27 every `normalise_every` steps, before the pair pass: rho_i^n = sum_{j in a} m_j W_ij /
        sum_{j in a} (m_j / rho_j) W_ij over the material a of i (self included) and the wall particles,
        each standing for i's material at rho_w = rho_i (1 + g . d_n / c_i^2) (hydrostatic across the wall,
        d_n the normal part of x_w - x_i, volume dx^d). Reads the view s, writes rho^n and the view q."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.fmask[i] == 1:
                si = self.s[i]
                xi = self._pos(si)
                ki = si[self.S_KIND]
                rhoi = si[self.S_RHO]
                hi = self.h0
                if ti.static(self.variable_h):
                    hi = si[self.S_H]
                w0 = kernels.w(0.0, hi, self.dim)
                num = si[self.S_M] * w0
                den = si[self.S_M] / rhoi * w0
                c2i = self._sound_speed(ki, rhoi) ** 2
                for k in range(self.nbr_walls(i), self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    sj = self.s[j]
                    kj = sj[self.S_KIND]
                    same = kj == ki
                    if kj != WALL and not same:
                        continue
                    hij = self._h_pair(hi, sj)
                    rij = operators.rel(xi, self._pos(sj), self.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * hij * hij or r2 == 0.0:
                        continue
                    wij = kernels.w(ti.sqrt(r2), hij, self.dim)
                    if kj == WALL:
                        # the wall's mirror image of i's material, hydrostatic across the wall: without it
                        # eq 27 averages the row next to a floor with the rows above only (lighter)
                        nrm = self.normal[j]
                        dxn = (-rij).dot(nrm) * nrm
                        num += rhoi * (1.0 + self.g.dot(dxn) / c2i) * self.vol0 * wij
                        den += self.vol0 * wij
                    else:
                        mj = sj[self.S_M]
                        num += mj * wij
                        den += mj / sj[self.S_RHO] * wij
                self.rho[i] = num / den
                self._pack_q(i, dt, w1, w2)

    @ti.func
    def _wall_source(self, i):
        """Whether particle i gives the wall particles it sees a pressure (walls.WallPressure): fluid."""
        return self.fmask[i] == 1

    @ti.func
    def _wall_pressure_seen(self, i, j):
        """Kernel weight and pressure that fluid particle i gives wall particle j for output: its own,
        extrapolated with hydrostatic correction (walls.wall_pressure). The step itself needs no wall
        pressure field: each fluid particle sees a wall particle with its own extrapolated value (see
        `_k_pairs`)."""
        xi = self.xf(i)
        hi = self.h0
        if ti.static(self.variable_h):
            hi = ti.cast(self.h[i], float)
        hij = self._h_pair(hi, self.s[j])
        r = operators.rel(xi, self.xf(j), self.period).norm()
        wij = 0.0
        pw = 0.0
        if r < 2.0 * hij:
            wij = kernels.w(r, hij, self.dim)
            xw = xi - operators.rel(xi, self.xf(j), self.period)
            pw = walls.wall_pressure(self.p[i], self.rhof(i), self.g, xw, xi)
        return wij, pw

    @ti.kernel
    def _k_pairs(self, dt: float, out: ti.types.ndarray()):
        """`_pair_passes`, its reductions written into `out` (a host array: the CPU's way)."""
        red = self._pair_passes(dt)
        for k in ti.static(range(self.n_red)):
            out[k] = red[k]

    @ti.kernel
    def _k_pairs_ret(self, dt: float) -> ti.types.vector(_NRET, ti.f64):
        """`_pair_passes`, its reductions returned, zero-padded to _NRET (GPUs: RETURN_REDUCTIONS)."""
        out = ti.Vector.zero(ti.f64, _NRET)
        red = self._pair_passes(dt)
        for k in ti.static(range(self.n_red)):
            out[k] = ti.cast(red[k], ti.f64)
        return out

    @ti.func
    def _pair_passes(self, dt):
        """The fluid's pair pass (`_fluid_pass`), then the soil's passes (soil_step.SoilPasses.passes): one
        launch, loops one after the other; the reductions of all of them in one vector (the fluid's
        _NRED, then the soil's)."""
        red = self._fluid_pass(dt)
        if ti.static(not self.has_soil):
            return red
        rs = self.soil.passes(dt)
        return ti.Vector([red[k] for k in ti.static(range(_NRED))] + [rs[k] for k in ti.static(range(self.soil.nred))])

    @ti.func
    def _fluid_pass(self, dt):
        """The pair pass at x^{n+1} with v^{n+1/2}, one walk over each fluid particle's neighbours for:
        - continuity: D_i = sum_j V_j (v_j - v_i) . grad_i W_ij (eq 25 in volume form, V_j = m_j / rho_j^n;
          walls with the virtual velocity of eq 50-51; less the density diffusion delta h c0 sum_j 2 (rho_j -
          rho_i - rho^H_ji) (-dW/dr / r) V_j / rho_i between water particles where wcsph.density_diffusion
          is on, with its gradient correction -(G_i + G_j) . (x_j - x_i) / 2 in the bracket where
          density_diffusion_form is `gradient`, G from the last pass, the new G_i written for the next),
          rho^{n+1} = rho^n (1 - D_i dt) (eq 48),
          h^{n+1} = h^n (1 + D_i dt / d) (eq 52), the XSPH correction (eq 53), then the equations of state
          (eq 39-41); D_i is kept for the next two predictions of `_pack_q`;
        - forces with the predicted rho~, p~ of the view q: eq 34 (pressure; Morris viscosity with
          v^{n+1/2}), eq 36, eq 54 and gravity.
        With pore water at its own volume (`partial`, wcsph.soil.pore_water: pore_volume; docs/biot.md) a water
        neighbour counts with V_j = m_j / (n_j rho_j), and the continuity's D_i is the divergence of the
        mixture's volume flux n v + (1 - n) v_s over n_i (n and v_s of the drag passes, `soil.nvs`); the
        pressure force on the particle, over n_i, is the force on its mixture volume, whose share (1 - n_i)
        `soil.gpore` keeps for the soil (its pore-pressure force, handed out by the drag passes).
        Soil particles take their stress update in the same loop (soil_step.py). Reductions: kinetic energy,
        max speed, water volume, min h/|a|, min h/c, non-finite count, first bad id, min h, air volume
        (returned).
        With dt = 0 (initial_diagnostics) the density, pressure, h and XSPH correction stay as they are."""
        ke = 0.0
        vmax = 0.0
        vol = 0.0
        vol_air = 0.0
        h_over_a = 1.0e30
        h_over_c = 1.0e30
        hmin = 1.0e30
        bad = 0.0
        first_bad = 2.0e9
        ti.loop_config(serialize=self.serial)
        for m in range(self.n if ti.static(self.exact_grid) else self.n_moving[None]):  # moving_ids
            i = self.moving_ids[m]
            if self.fmask[i] == 1:
                si = self.s[i]
                qi = self.q[i]
                xi = self._pos(si)
                vi = self._vel(si)
                rho_n = self.rho[i]
                rhoi = qi[self.Q_RHO]
                pri = qi[self.Q_PR]
                pi = pri * rhoi * rhoi
                mi = si[self.S_M]
                ki = self.kind[i]
                hi = self.h0
                if ti.static(self.variable_h):
                    hi = qi[self.Q_H]
                nui = self._nu(ki)
                cavi = self._c_av(ki)
                cohi = self._cohesion(ki)
                acc = self.g
                div = 0.0
                dif = 0.0
                # the density diffusion's gradient correction: G_i of the last pass, and this pass's sums for
                # the new one, B = sum_j V_j grad_i W_ij (x_j - x_i)^T and sum_j (rho_j - rho_i - rho^H_ji)
                # grad_i W_ij V_j
                g_old = ti.Vector.zero(float, self.dim)
                g_sum = ti.Vector.zero(float, self.dim)
                b_mat = ti.Matrix.zero(float, self.dim, self.dim)
                if ti.static(self.dd_grad):
                    for d in ti.static(range(self.dim)):
                        g_old[d] = si[self.S_G + d]
                xs = ti.Vector.zero(float, self.dim)
                n_i = 1.0
                wi = vi
                if ti.static(self.partial):  # noqa: SIM102
                    if ki == WATER:
                        nvi = self.soil.nvs[i]
                        n_i = nvi[0]
                        for d in ti.static(range(self.dim)):
                            wi[d] = n_i * vi[d] + (1.0 - n_i) * nvi[1 + d]
                # pressure acceleration, and the share of it the walls take through the gradient at i
                accp = ti.Vector.zero(float, self.dim)
                m_wall = ti.Matrix.zero(float, self.dim, self.dim)
                hyd_t = ti.Vector.zero(float, self.dim)
                # walls and fluid: soil couples by drag only (soil_step.py)
                for k in range(self.nbr_walls(i), self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    sj = self.s[j]
                    qj = self.q[j]
                    hij = self.h0
                    if ti.static(self.variable_h):
                        hij = 0.5 * (hi + qj[self.Q_H])
                    rij = operators.rel(xi, self._pos(sj), self.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * hij * hij or r2 == 0.0:
                        continue
                    r = ti.sqrt(r2)
                    wij = 0.0
                    dwdr = 0.0
                    if ti.static(self.xsph_on):
                        wij, dwdr = kernels.w_and_dw_dr(r, hij, self.dim)
                    else:
                        dwdr = kernels.dw_dr(r, hij, self.dim)
                    gw = dwdr / r * rij
                    f_ij = operators.laplacian_weight(r, hij, self.eta2, self.dim)
                    kj = sj[self.S_KIND]
                    if kj == WALL:
                        # boundary particle: the virtual velocity of eq 50-51, the density of i and the
                        # pressure of i extrapolated hydrostatically to it (Neumann condition)
                        db = self.wdepth[j]
                        nrm = self.normal[j]
                        beta = walls.boundary_beta(db, rij.dot(nrm) - db, self.beta_max)
                        vij = walls.boundary_relative_velocity(vi - self._vel(sj), nrm, beta, self.no_slip)
                        if ti.static(self.partial):
                            div -= self.vol0 * walls.boundary_relative_velocity(wi - self._vel(sj), nrm, beta,
                                                                                self.no_slip).dot(gw)
                        else:
                            div -= self.vol0 * vij.dot(gw)
                        mj = rhoi * self.vol0
                        # pressure at the wall particle: hydrostatic across the wall, the gradient at i
                        # along it (mirror image of the excess pressure), p_w = p_i + rho_i g . d_n +
                        # G_i . d_t with G_i = -rho_i a_p (solved below)
                        dxw = -rij
                        dxn = dxw.dot(nrm) * nrm
                        pw = pi + rhoi * self.g.dot(dxn)
                        accp += terms.pressure_same_material(mj, pri, pw / (rhoi * rhoi), gw)
                        m_wall += self.vol0 * gw.outer_product(dxw - dxn)
                        hyd_t -= self.vol0 * self.g.dot(dxw - dxn) * gw
                        acc += operators.variable_laplacian_pair(mj, rhoi, nui, rhoi, nui, f_ij) * vij
                        if ti.static(self.av_on):
                            pij = terms.artificial_viscosity(vij, rij, r2, hij, cavi, rhoi, self.av_alpha,
                                                             self.av_beta, self.av_eps)
                            acc -= mj * pij * gw
                    else:
                        vij = vi - self._vel(sj)
                        mj = sj[self.S_M]
                        if ti.static(self.partial):
                            wj = self._vel(sj)
                            if kj == WATER:
                                nvj = self.soil.nvs[j]
                                mj /= nvj[0]
                                for d in ti.static(range(self.dim)):
                                    wj[d] = nvj[0] * wj[d] + (1.0 - nvj[0]) * nvj[1 + d]
                            div -= mj / sj[self.S_RHO] * (wi - wj).dot(gw)
                        else:
                            div -= mj / sj[self.S_RHO] * vij.dot(gw)
                        if ti.static(self.dd_on):  # noqa: SIM102 (compile-time if): density diffusion
                            if ki == WATER and kj == ki:
                                rho_h = self.dd_h * self.g.dot(-rij)  # hydrostatic rho_j - rho_i
                                drho = sj[self.S_RHO] - si[self.S_RHO] - rho_h
                                vj = mj / sj[self.S_RHO]
                                if ti.static(self.dd_grad):
                                    g_sum += drho * vj * gw
                                    b_mat += vj * gw.outer_product(-rij)
                                    g_j = ti.Vector.zero(float, self.dim)
                                    for d in ti.static(range(self.dim)):
                                        g_j[d] = sj[self.S_G + d]
                                    drho -= 0.5 * (g_old + g_j).dot(-rij)
                                dif += 2.0 * drho * (-dwdr / r) * vj
                        # XSPH within the particle's own material: across the 800:1 jump it would move an
                        # air particle with the water around it, unseen by the continuity and the walls
                        if ti.static(self.xsph_on):  # noqa: SIM102 (compile-time if)
                            if kj == ki:
                                xs += terms.xsph(mj, si[self.S_RHO], sj[self.S_RHO], vij, wij)
                        rhoj = qj[self.Q_RHO]
                        prj = qj[self.Q_PR]
                        same = True
                        if ti.static(self.has_air):
                            same = kj == ki
                        if same:
                            accp += terms.pressure_same_material(mj, pri, prj, gw)
                            acc += operators.variable_laplacian_pair(mj, rhoi, nui, rhoj, nui, f_ij) * vij
                            if ti.static(self.av_on):
                                pij = terms.artificial_viscosity(vij, rij, r2, hij, cavi, 0.5 * (rhoi + rhoj),
                                                                 self.av_alpha, self.av_beta, self.av_eps)
                                acc -= mj * pij * gw
                            if ti.static(self.cohesion_on):
                                acc += terms.cohesion(cohi, mj, gw)
                        else:
                            accp += terms.pressure_interface(mi, mi / rhoi, mj / rhoj, pi, prj * rhoj * rhoj,
                                                             gw)
                            nuj = self._nu(ti.cast(kj, ti.i32))
                            acc += operators.variable_laplacian_pair(mj, rhoi, nui, rhoj, nuj, f_ij) * vij
                if ti.static(self.partial):  # n_i D_f rho / Dt = -rho div(n v_f + (1 - n) v_s)
                    div /= n_i
                if ti.static(self.dd_on):  # d rho / dt = -rho D + delta h c0 dif, written as D
                    div -= self.dd_coef * dif / si[self.S_RHO]
                if ti.static(self.dd_grad):  # G_i = B^-1 sum: exact on a linear field; none where B is
                    g_new = ti.Vector.zero(float, self.dim)  # far from I (a free surface, few neighbours)
                    if ki == WATER and dt > 0.0 and b_mat.determinant() > DD_GRAD_MIN_DET:
                        g_new = b_mat.inverse() @ g_sum
                    self.grad_rho[i] = g_new
                # a_p = A_p + m_wall a_p (the walls' tangential terms carry G_i = -rho_i a_p)
                a_p = walls.wall_mirror_solve(accp, m_wall, hyd_t)
                acc += a_p
                if ti.static(self.partial):  # the same force on the soil's share (1 - n_i) of i's mixture volume
                    self.soil.gpore[i] = (1.0 - n_i) / n_i * mi * a_p
                self.a[i] = acc
                self.rate[i] = ti.Vector([div, self.rate[i][0]])
                # density and h accumulate in f64 (the fields are f64), the EOS is evaluated there too
                rho64 = rho_n
                if dt > 0.0:
                    dd = ti.cast(div * dt, ti.f64)  # 1 - dd in f32 would round small rates away
                    rho64 = rho_n * (1.0 - dd)
                    self.rho[i] = rho64
                    self.p[i] = ti.cast(self._eos_pressure(ki, rho64), float)
                    if ti.static(self.xsph_on):
                        self.xs[i] = self.xsph_eps * xs
                    if ti.static(self.variable_h):
                        self.h[i] = ti.min(ti.max(self.h[i] * (1.0 + dd / self.dim), self.h_lo), self.h_hi)
                rho = ti.cast(rho64, float)
                # reductions
                voli = mi / rho
                # synchronised velocity at this time; with soil the drag of the step before (this step's
                # comes after this pass), as the kick and the frames take it
                vs = vi + 0.5 * dt * acc
                if ti.static(self.has_soil):
                    vs += 0.5 * dt * self.soil.adrag[i]
                s2 = vs.dot(vs)
                ke += 0.5 * mi * s2
                ti.atomic_max(vmax, ti.sqrt(s2))
                if self._is_air(ki):
                    vol_air += voli
                else:
                    vol += voli
                an = acc.norm()
                if an > 0.0:
                    ti.atomic_min(h_over_a, hi / an)
                # pore water at its own volume: its pressure answers div(q) / n (storage n / K_f), a sound
                # speed c / sqrt(n_i)
                ti.atomic_min(h_over_c, hi * ti.sqrt(n_i) / self._sound_speed(ki, rho))
                ti.atomic_min(hmin, hi)
                val = s2 + pi + xi.sum() + rho
                if ti.math.isnan(val) or ti.math.isinf(val):
                    bad += 1.0
                    ti.atomic_min(first_bad, float(self.ids[i]))
            if ti.static(self.has_soil):  # noqa: SIM102 (compile-time if)
                if self.fmask[i] == 2:
                    self.soil.stress_at(i, dt)
        return ti.Vector([ke, vmax, vol, h_over_a, h_over_c, bad, first_bad, hmin, vol_air])

    # ------------------------------------------------------------------ step
    def neighbour_search(self, dt: float = 0.0, w=(0.0, 0.0)):
        """Sort into cells, reorder every particle array, rebuild the lists with the Verlet skin; then the
        packed views for a pair pass over a step of length dt with the prediction weights w (`_weights`)."""
        reorder = self.searches % self.reorder_every == 0
        self.searches += 1
        self._sort_and_reorder(reorder)
        self._k_mask()
        self._k_moving_list()
        self.r_list = min(self.cell, 2.0 * self.hmax + self.skin)
        try:
            self.grid.build_neighbour_lists(self.x, self.fmask, self.n, self.r_list, self.ids,
                                            in_place=reorder, group=self.group if self.has_soil else None)
        except NeighbourOverflowError as exc:
            raise guard.neighbour_overflow_error(self.step_count, self.time, exc) from None
        self._k_after_build(dt, w[0], w[1])
        self.rebuilds += 1

    def _weights(self, dt: float) -> tuple[float, float]:
        return prediction_weights(dt, self.dt_prev, self.dt_prev2, self.rates_known)

    def _pairs(self, dt: float):
        """The pair pass and the soil's passes (one kernel), then their reductions: diagnostics, the
        non-finite checks (the fluid's first)."""
        if self.returns_reductions:
            self.red_pairs[:] = self._step_kernels[1](dt).to_numpy()[: self.n_red]
        else:
            self._step_kernels[1](dt, self.red_pairs)
        self.rates_known = min(self.rates_known + 1, 2)
        self.red = self.red_pairs[:_NRED].copy()
        r = self.red
        self.last = {"kinetic_energy": float(r[0]), "max_speed": float(r[1]), "water_volume": float(r[2]),
                     "air_volume": float(r[8])}
        if r[5] > 0:
            raise guard.non_finite_error(self.step_count, self.time, int(r[5]), int(r[6]),
                                         "position, velocity, density or pressure")
        if self.has_soil:
            self.soil.after_passes(self.red_pairs[_NRED:])

    def step(self, dt: float) -> dict:
        t0 = _time.perf_counter()
        if self.moving:
            self.motion.set_step(self.time, self.time + dt)
        w = self._weights(dt)
        if self.returns_reductions:
            self.red_kick[:] = self._step_kernels[0](dt, self.dt_prev, w[0], w[1]).to_numpy()
        else:
            self._step_kernels[0](dt, self.dt_prev, w[0], w[1], self.red_kick)
        d2max, hmax = self.red_kick
        if self.variable_h:
            self.hmax = float(hmax)
        self.step_count += 1
        self.time += dt
        t0 = self._tick("update", t0)
        released = self.inflow.release(self.time - dt, self.time) if self.inflow is not None else ()
        if len(released):
            activate(self, released)
        if len(released) or 2.0 * math.sqrt(max(float(d2max), 0.0)) + 2.0 * self.hmax > self.r_list:
            self.neighbour_search(dt, w)
        t0 = self._tick("neighbours", t0)
        if self.normalised and self.step_count % self.normalise_every == 0:
            self._k_normalise(dt, w[0], w[1])
        self._pairs(dt)
        self._tick("pairs", t0)
        self.dt_prev2 = self.dt_prev
        self.dt_prev = dt
        return self.last

    def initial_diagnostics(self) -> dict:
        """Neighbour lists, forces at t = 0 (the first step needs a^0) and the divergence D^0 that the first
        steps' predictions start from. The soil's pore pressure and water presence are interpolated before
        its forces, so that a^0 of the soil sees its pore pressure. With pore water at its own volume
        (`partial`) the first pass gives each water particle its porosity n_i, the particle's mass becomes
        n_i rho dx^d (water placed in the soil at the lattice's spacing fills its pores) and the pass is
        taken again with those masses."""
        self.neighbour_search()
        self._pairs(0.0)
        if self.partial:
            self._k_pore_masses()
            self.rates_known = 0
            self._pairs(0.0)
        return self.last

    @ti.kernel
    def _k_pore_masses(self):
        """m_i <- n_i m_i for each water particle (n_i of the drag pass, 1 in free water), and its view s."""
        for i in range(self.n):
            if self.kind[i] == WATER:
                self.m[i] *= self.soil.nvs[i][0]
                self.s[i][self.S_M] = self.m[i]

    def propose_dt(self) -> tuple[float, int]:
        """Time step of eq 49 from the forces just computed: min(cfl min h/c, force min sqrt(h/|a|),
        viscous h_min^2 / nu_max), with its limit code. The seed prints the third limit as
        0.125 min sqrt(h / v), dimensionally inconsistent; this is Morris et al.'s viscous condition
        0.125 h^2 / nu that the seed cites for its viscous term."""
        ts = self.cfg.timestep
        r = self.red
        limits = {DT_CFL: ts.cfl * float(r[4]), DT_FORCE: ts.force * math.sqrt(float(r[3]))}
        if self.nu_max > 0.0:
            limits[DT_VISCOUS] = ts.viscous * float(r[7]) ** 2 / self.nu_max
        if self.has_soil:
            rs = self.soil.red_s
            limits[DT_CFL] = min(limits[DT_CFL], ts.cfl * float(rs[3]))
            limits[DT_FORCE] = min(limits[DT_FORCE], ts.force * math.sqrt(float(rs[2])))
        which = min(limits, key=limits.get)
        if limits[which] < ts.min:
            raise guard.time_step_error(self.step_count, self.time, limits[which], ts.min, "eq 49")
        return limits[which], which

    #: guard.max_pore_pressure when not given: this multiple of pore_pressure_scale(). The shipped soil cases
    #: reach at most 1.82 of the scale (one particle at the dry levee's toe as the river is put against it,
    #: dx 0.01); the pore-water bursts it is there for, 5-25 (docs/biot.md, "The guard's pore-pressure bound")
    pore_pressure_factor = 3.0

    def pore_pressure_scale(self) -> float:
        """g H (rho_w + (1 - n) rho_s) + |u0|, H the tank's height: the total vertical stress at the floor of
        a tank full of saturated soil, the most a pore pressure at rest can carry, plus the largest initial
        excess pore pressure u0 (wcsph.soil.initial_excess_pressure)."""
        u0 = self.cfg.wcsph.soil.initial_excess_pressure
        excess = abs(u0.amplitude) if u0 is not None else 0.0
        return (self.rho_w + self.soil.rho_sl) * self.g_abs * float(self.cfg.tank.size[-1]) + excess

    def max_pore_pressure_bound(self) -> float | None:
        """Pore-pressure magnitude (Pa) of a soil particle above which the guard stops the run:
        `guard.max_pore_pressure`, or pore_pressure_factor x pore_pressure_scale(); None without soil or
        (by default) without gravity."""
        if not self.has_soil:
            return None
        if self.cfg.guard.max_pore_pressure is not None:
            return self.cfg.guard.max_pore_pressure
        return self.pore_pressure_factor * self.pore_pressure_scale() if self.g_abs > 0.0 else None

    # ------------------------------------------------------------------ output
    def fields_by_id(self) -> dict:
        """Per-particle arrays in id order (SPEC 8 frame fields); pressures relative to the ambient."""
        self.wall_pressure.update()
        order = self._id_order()
        kind = self.kind.to_numpy()[order]
        v = self.v.to_numpy()[order]
        acc = self.a.to_numpy()[order]
        if self.has_soil:  # the kick's acceleration includes the drag (soil_step.py), the force pass's does not
            acc = acc + self.soil.adrag.to_numpy()[order]
        vel = v + 0.5 * self.dt_prev * acc
        wall = kind == WALL
        vel[wall] = v[wall]  # zero, or a moving obstacle's velocity
        rho = self.rho.to_numpy()[order]
        rho = np.where(kind == WALL, self.rho_w, rho)
        out = {
            "position": self.x.to_numpy()[order],
            "velocity": vel,
            "pressure": self.p.to_numpy()[order],
            "density": rho,
            "active": self.active.to_numpy()[order].astype(bool),
        }
        if self.has_soil:
            out.update(self.soil.output(order))
        return out

    # ------------------------------------------------------------------ checkpoints
    #: fields that carry over from one step to the next: leap-frog state, the packed views, positions at
    #: the last list build; with the Verlet neighbour lists themselves (kept between rebuilds) and the
    #: soil's own (SoilPasses.state_fields: one-element fields in a scene without soil).
    state_fields = ("x", "v", "a", "xs", "rate", "normal", "x0", "rho", "p", "h", "m", "wdepth", "kind",
                    "ids", "active", "fmask", "s", "q", "wall_body", "wall_origin")
    state_scalars = ("step_count", "time", "removed_total", "dt_prev", "dt_prev2", "rates_known", "r_list",
                     "hmax", "rebuilds", "red")

    @property
    def inflow_state(self) -> np.ndarray:
        """Rows and volume released and gate of each river inflow (inflow.py), for checkpoints."""
        return self.inflow.state

    @inflow_state.setter
    def inflow_state(self, value) -> None:
        self.inflow.state = value

    def observe_probes(self, t: float, readings: dict) -> None:
        """The probes' readings at t: a river inflow held at a level opens or closes (inflow.py)."""
        if self.inflow is not None:
            self.inflow.observe(t, readings)

    def state(self) -> dict:
        """Full state for a checkpoint, {name: numpy array or scalar} (sph/state.py)."""
        from ..sph.state import snapshot

        out = snapshot(self, self.state_fields, self.state_scalars, self.grid)
        out.update(snapshot(self.soil, self.soil.state_fields, self.soil.state_scalars))
        return out

    def load_state(self, state: dict) -> None:
        """Continue from a `state()` of a solver built from the same config."""
        from ..sph.state import restore

        soil_keys = (*self.soil.state_fields, *self.soil.state_scalars)
        restore(self, {k: v for k, v in state.items() if k not in soil_keys}, self.state_fields,
                self.state_scalars, self.grid)
        restore(self.soil, {k: v for k, v in state.items() if k in soil_keys}, self.soil.state_fields,
                self.soil.state_scalars)
        self._k_moving_list()  # a function of fmask, which the state holds
        if self.has_soil:  # where each list's groups start (and their order, for a state saved ungrouped)
            self._k_mask()
            self.grid.group_rows(self.group, self.n)


def deal_threads(has_soil: bool, serial: bool) -> int:
    """How many threads the moving list is dealt to (`_k_moving_list`): the CPU's threads in a parallel
    scene with soil, else 1 (the list stays in cell order)."""
    cfg = ti.lang.impl.current_cfg()
    if has_soil and not serial and on_cpu():
        return max(1, int(cfg.cpu_max_num_threads))
    return 1


def prediction_weights(dt: float, dt_prev: float, dt_prev2: float, known: int) -> tuple[float, float]:
    """Weights (w1, w2) of the divergence predicted for the step dt, D~ = w1 D^{n-1/2} + w2 D^{n-3/2}: the
    line through the last two pair passes' divergences (the rates of the half steps t^{n-1/2}, t^{n-3/2})
    taken to t^{n+1/2}, w1 = 1 + c, w2 = -c with c = (dt + dt_prev) / (dt_prev + dt_prev2); the last one
    alone after one pass (known = 1), none before (docs/wcsph.md, "One step")."""
    if known >= 2:
        c = (dt + dt_prev) / (dt_prev + dt_prev2)
        return 1.0 + c, -c
    return (1.0, 0.0) if known == 1 else (0.0, 0.0)


def _exponent(gamma: float):
    """An integral exponent as int, so that the EOS compiles (rho / rho0)^7 to multiplications."""
    return int(gamma) if float(gamma).is_integer() else float(gamma)
