"""Soil passes of mode wcsph_biot (seed 002 sections 2.3-2.5): the object WCSPHSolver holds as `soil`.

Soil particles (kind 2) are their own set overlapping the fluid sets (the seed's layers, fig 3); the
fluid pair terms skip them. Per step:

1. stress update (`stress_at`), in the pair pass of solver.py at x^{n+1} with v^{n+1/2}: velocity
   gradient from soil neighbours and walls (virtual velocity of eq 50-51), strain and spin rates
   (eq 37-38), density by eq 48, effective stress by eq 42-45 (soil.py).
2. force pass (`_forces_pass`), after the pair pass, one walk over the neighbours: the pore pressure p_i =
   sum_w V_j p_j W_ij / sum_w V_j W_ij from the water's new pressure (eq 5, Shepard-normalised) and the
   water presence, and eq 35 with eq 36, gravity, the pore-pressure force -grad p / rho_s (per unit
   soil mass, the (1 - n) grad p of the mixture theory over the soil's (1 - n) rho_s) and an optional
   damping (`wcsph.soil.fixed`: the skeleton is rigid, its acceleration and drag are zero).
3. drag passes (`_drag_water_pass`, `_drag_soil_pass`, `_drag_water_after_pass`): the water's mixture momentum
   inside the soil (pore part n under the water's forces, the rest moving with the soil) and eq 46-47
   between soil and water (and air, with the soil's conductivity for air) as pair forces F_ij = -F_ji
   (`_pair_drag`), implicit per pair (docs/biot.md),
   written to `adrag` which the next kick adds to the acceleration; their sum over all particles goes to
   /diagnostics/drag_sum (momentum check), the largest to drag_max (summed in the last drag pass).

Each pass reads of its neighbours only what the passes before it wrote: the force pass needs the new
stresses of the soil around (step 1) and the water's new pressures; each drag pass needs the one before.
Passes 2 and 3 are loops of the solver's pair kernel, after the fluid's loop (`passes`): one launch per step
for all of them, and one buffer of reductions read once by the host.
"""

import logging
import math

import numpy as np
import taichi as ti

from .. import guard
from ..config.schema import PORE_WATER_STIFFNESS
from ..scene import AIR, SOIL, WALL, WATER
from ..sph import kernels, operators, walls
from ..switches import held_soil_ids
from . import soil, terms

_NRED_S = 6  # kinetic energy, max speed, min h/|a|, min h/c, non-finite count, first bad id

log = logging.getLogger("taichi_sph")


@ti.data_oriented
class SoilPasses:
    """Soil state and passes of a WCSPHSolver `fl`, which holds the particle store they read and write
    (positions, velocities, the packed views, density, pressure, acceleration, neighbour lists) and calls
    `stress_at` from its pair pass and `forces` after it. The soil's own fields (effective stress, plastic
    strain, pore pressure, water presence, drag) are one element long in a scene without soil."""

    #: fields and host values that carry over from one step to the next (checkpoints, with the solver's)
    #: (phi_a, the air's presence, is scratch as amix and wmix: set by the force pass before the drag reads
    #: it in the same launch, neither state nor reordered with the particles)
    state_fields = ("sig", "eps_p", "pore", "phi_w", "adrag")
    state_scalars = ("red_s",)

    def __init__(self, fl, cfg, scene):
        self.fl = fl
        sw = fl.switches
        sp = cfg.wcsph.soil
        self.rho_g = sp.grain_density
        self.n0 = sp.porosity
        self.rho_sl = (1.0 - sp.porosity) * sp.grain_density
        self.e0 = sp.youngs_modulus
        self.p_ref = sp.reference_stress
        self.m_exp = sp.exponent
        self.p_floor = sp.stress_floor
        self.nu_s = sp.poisson
        self.k_fac = soil.bulk_modulus_factor(cfg.dim, sp.poisson)
        self.m_fac = soil.p_wave_factor(cfg.dim, sp.poisson)
        # yield surface tau_f = p sin(phi) + c cos(phi) (soil.py; `tan_phi` given: sin(phi) = tan_phi)
        self.phi_deg = sp.friction_angle_deg()
        self.sin_phi, self.c_cos = soil.yield_constants(self.phi_deg, sp.cohesion)
        # plastic flow rule: dilatancy angle psi (0: no plastic volume change)
        self.sin_psi = math.sin(math.radians(sp.dilatancy_angle))
        self.dilatant = bool(sw.soil_dilatancy)
        if sp.tension_cutoff is not None:
            self.t_cut = sp.tension_cutoff
        else:  # where tau_f vanishes: p = -c cot(phi)
            tan_mc = math.tan(math.radians(self.phi_deg))
            self.t_cut = sp.cohesion / tan_mc if tan_mc > 0 else 0.0
        # pore water stiff beside the skeleton (schema.PORE_WATER_STIFFNESS): K_f / M in the run file, and a
        # warning where a config's sound speed leaves the water softer
        self.run_attrs = {}
        m_soil = cfg.soil_modulus() if fl.has_soil and fl.n_water > 0 else None
        if m_soil is not None:
            ratio = fl.rho_w * fl.c_w**2 / m_soil
            share = cfg.pore_storage()  # the pore water's storage is share / K_f
            self.run_attrs["pore_water_modulus_ratio"] = ratio
            if ratio < PORE_WATER_STIFFNESS * share * (1.0 - 1e-9):
                log.warning("pore water K_f = rho_w c0^2 = %.4g Pa is %.3g x the soil's constrained modulus M = "
                            "%.4g Pa (below %g): consolidation runs at c_v = k M / gamma_w / (1 + %g M / K_f), "
                            "%.0f %% of the physical value; raise wcsph.water.sound_speed to %.4g m/s or more (or "
                            "leave it to its default), or check wcsph.soil.youngs_modulus, exponent, poisson",
                            fl.rho_w * fl.c_w**2, ratio, m_soil, PORE_WATER_STIFFNESS * share, share,
                            100.0 / (1.0 + share / ratio), cfg.pore_water_speed())
        self.alpha_s = sp.alpha
        self.g_over_k = fl.g_abs / sp.permeability
        # the drag between soil and air (eq 46 with the air's density and the soil's conductivity for air)
        k_air = cfg.air_conductivity()
        self.g_over_ka = fl.g_abs / k_air if (fl.soil_air and k_air) else 0.0
        self.damping = sp.damping
        # rigid skeleton: no acceleration, no drag on the soil, no soil dt limit
        self.soil_fixed = sw.soil_fixed
        # soil blocks held rigid on their own (`soil_blocks[k].fixed`: a permeable base); by particle id
        self.fixed_ids = held_soil_ids(cfg, scene)
        self.block_fixed = sw.soil_blocks_fixed
        self._fields(fl.n)

    def _fields(self, n):
        fl = self.fl
        ns = n if fl.has_soil else 1
        dim = fl.dim
        self.sig = ti.Matrix.field(dim, dim, float, ns)  # effective stress, compression positive
        self.eps_p = ti.field(float, ns)  # accumulated plastic shear strain
        self.pore = ti.field(float, ns)  # pore pressure at soil particles (gauge)
        self.phi_w = ti.field(float, ns)  # water presence sum_w V_j W_ij at soil particles
        self.phi_a = ti.field(float, ns)  # air presence at soil particles (the same, over the air; scratch)
        self.adrag = ti.Vector.field(dim, float, ns)  # drag acceleration of eq 46, added by the kick
        # water acceleration without drag inside the soil (scratch of the drag pass, not carried over)
        self.amix = ti.Vector.field(dim, float, ns)
        # the Biot drag force of eq 46-47 on each particle (N; N/m in 2D), the pair part only: the water's
        # n_i phi_s (g / k) (u - v_s) and the soil's C_s phi_w (u - v_s) times their masses (scratch)
        self.fdrag = ti.Vector.field(dim, float, ns)
        # reductions in the solver's buffer after its own: the force pass's _NRED_S, then the momentum check
        # of the drag: the sum over all particles of fdrag (dim) and the largest |fdrag|
        self.nred = _NRED_S + dim + 1
        # per water particle n_i, f_i = phi_s / sum_soil V_j W_ij and phi_s of the pair drag (scratch)
        self.wmix = ti.Vector.field(3, float, ns)
        # pore water at its own volume (wcsph.soil.pore_water: pore_volume): per water particle n_i and the
        # soil's mean velocity around it, of the last drag pass (reordered with the particles: the fluid
        # pass reads them at the start of the next step)
        self.nvs = ti.Vector.field(dim + 1, float, n if fl.partial else 1)
        # pore water at its own volume: per water particle the pressure force on the soil's share (1 - n_i) of
        # its mixture volume (N; N/m in 2D), divided by sum_soil V_j W_ij in the drag pass (scratch)
        self.gpore = ti.Vector.field(dim, float, n if fl.partial else 1)
        # 1 for a particle of a fixed soil block, indexed by particle id (never reordered, no state)
        self.sfix = ti.field(ti.i32, n if self.block_fixed else 1)
        if self.block_fixed:
            held = np.zeros(n, np.int32)
            held[self.fixed_ids] = 1
            self.sfix.from_numpy(held)
        self.red_s = np.array([0.0, 0.0, 1e30, 1e30, 0.0, 0.0])
        #: per-particle fields the solver reorders with its own when it sorts particles into cells
        self.particle_fields = []
        if fl.has_soil:
            self.particle_fields = [self.sig, self.eps_p, self.pore, self.phi_w, self.adrag]
            self.adrag.fill(0.0)
        if fl.partial:
            self.particle_fields.append(self.nvs)
            self.state_fields = (*type(self).state_fields, "nvs")
            self.nvs.fill(1.0)  # n_i = 1 (free water) until the first drag pass; v_s bar then has no weight

    # ------------------------------------------------------------------ kernels
    @ti.func
    def stress_at(self, i, dt):
        """Soil particle i in the pair pass of solver.py: strain and spin rates (eq 37-38), density (eq 48),
        stress (eq 42-45). Reads the packed view s of its soil and wall neighbours only (the water's
        pressure of this step is not known yet: `_forces_pass` interpolates it after the pass).
        A wall particle's velocity relative to i: across its face as eq 50 gives it; along the face of a
        slip wall, the soil's own velocity carried there by the gradient at i (the mirror image of the
        field, as the stress takes in `_forces_pass`; walls.wall_mirror_solve_rows). Taking i's own
        velocity there, as before, left the walls' share of the kernel out of d v_t / d x_t: soil beside a
        slip wall was softer in compression along it, and Terzaghi's layer settled 7.2 / 3.4 / 1.7 % more
        than its constrained modulus gives in tanks 5 / 10 / 20 particles wide (docs/biot.md)."""
        fl = self.fl
        si = fl.s[i]
        xi = fl._pos(si)
        vi = fl._vel(si)
        h = fl.h0
        L = ti.Matrix.zero(float, fl.dim, fl.dim)
        m_wall = ti.Matrix.zero(float, fl.dim, fl.dim)  # sum over slip walls of V grad W (x) d_t
        for k in range(fl.nbr_fluid(i)):  # soil and walls
            j = fl.grid.nbr[i, k]
            sj = fl.s[j]
            kj = sj[fl.S_KIND]
            rij = operators.rel(xi, fl._pos(sj), fl.period)
            r2 = rij.dot(rij)
            if r2 >= 4.0 * h * h or r2 == 0.0:
                continue
            r = ti.sqrt(r2)
            gw = kernels.dw_dr(r, h, fl.dim) / r * rij
            if kj == SOIL:
                L += sj[fl.S_M] / sj[fl.S_RHO] * (fl._vel(sj) - vi).outer_product(gw)
            else:
                db = fl.wdepth[j]
                nrm = fl.normal[j]
                beta = walls.boundary_beta(db, rij.dot(nrm) - db, fl.beta_max)
                vij = walls.boundary_relative_velocity(vi - fl.v[j], nrm, beta, fl.no_slip)
                L -= fl.vol0 * vij.outer_product(gw)
                if ti.static(not fl.no_slip):
                    dxw = -rij
                    m_wall += fl.vol0 * gw.outer_product(dxw - dxw.dot(nrm) * nrm)
        if ti.static(not fl.no_slip):
            L = walls.wall_mirror_solve_rows(L, m_wall)
        # dt = 0 (the pass of initial_diagnostics) leaves the stress as it is: the return mapping would
        # otherwise re-project a stress lying on the yield surface and move it by rounding
        if dt > 0.0:
            sig, dgam, _e = soil.stress_update(self.sig[i], L, dt, self.e0, self.p_ref, self.m_exp,
                                               self.p_floor, self.nu_s, self.k_fac, self.sin_phi, self.c_cos,
                                               self.t_cut, fl.dim, self.sin_psi, self.dilatant)
            self.sig[i] = sig
            self.eps_p[i] += dgam
        fl.rho[i] = fl.rho[i] * (1.0 - ti.cast(L.trace() * dt, ti.f64))  # f64: small rates stay
        if ti.static(not fl.coupled):
            self.pore[i] = 0.0
            fl.p[i] = 0.0
            self.phi_w[i] = 0.0

    @ti.func
    def passes(self, dt):
        """The soil's passes after the solver's pair loop, each a loop of the same kernel: forces, then the
        drag (coupled scenes); returns their reductions (`nred`: the force pass's, then the drag's)."""
        rs = self._forces_pass(dt)
        rd = ti.Vector.zero(float, self.fl.dim + 1)
        if ti.static(self.fl.drag_on):
            self._drag_water_pass(dt)
            self._drag_soil_pass(dt)
            rd = self._drag_water_after_pass(dt)
        return ti.Vector([rs[k] for k in ti.static(range(_NRED_S))]
                         + [rd[k] for k in ti.static(range(self.fl.dim + 1))])

    @ti.func
    def _forces_pass(self, dt):
        """One walk over each soil particle's neighbours for the pore pressure, the water presence and the
        forces: p_i = sum_w V_j p_j W_ij / sum_w V_j W_ij from the water's new pressure (eq 5,
        Shepard-normalised), the wetness phi_w, then eq 35 with eq 36, gravity, the pore-pressure force,
        damping. The terms that need p_i or phi_w are summed without them and combined after the walk:
        sum_w V_j (p_j - p_i) grad W = sum_w V_j (p_j - p0) grad W - (p_i - p0) sum_w V_j grad W, with p0 the
        particle's pore pressure of the step before (so that the sums hold differences, not the pressure
        itself, in f32). With pore water at its own volume (`fl.partial`) the pore-pressure force is not
        taken here: each water particle hands the soil around it the share (1 - n_i) of the pressure force
        on its mixture volume (`_drag_water_pass`, docs/biot.md, "Pore water at its own volume"); p_i and
        phi_w are still taken, for the frames, the guard and the walls' buoyant weight. Reductions: kinetic
        energy, max speed, min h/|a|, min h/c, non-finite count, first bad id (returned)."""
        fl = self.fl
        ke = 0.0
        vmax = 0.0
        h_over_a = 1.0e30
        h_over_c = 1.0e30
        bad = 0.0
        first_bad = 2.0e9
        h = fl.h0
        ti.loop_config(serialize=fl.serial)
        for m in range(fl.n if ti.static(fl.exact_grid) else fl.n_moving[None]):  # solver.moving_ids
            i = fl.moving_ids[m]
            if fl.fmask[i] == 2:
                si = fl.s[i]
                xi = fl._pos(si)
                vi = fl._vel(si)
                rhoi = fl.rhof(i)
                sigi = self.sig[i]
                si_r = sigi / (rhoi * rhoi)
                p_i, _s, _t = soil.mean_and_shear(sigi, fl.dim)
                ci = ti.sqrt(self.m_fac * soil.youngs_modulus(p_i, self.e0, self.p_ref, self.m_exp, self.p_floor) / rhoi)
                p0 = self.pore[i]
                acc = fl.g
                # stress acceleration; the walls carry the stress and the pore pressure across their faces
                # by the equilibrium gradient and along them by the gradient at i (walls.wall_mirror_solve):
                # m_wall = sum V grad W (x) d_t and g_t = sum V (g . d_t) grad W over the walls serve both
                accs = ti.Vector.zero(float, fl.dim)
                m_wall = ti.Matrix.zero(float, fl.dim, fl.dim)
                g_t = ti.Vector.zero(float, fl.dim)
                g_n = ti.Vector.zero(float, fl.dim)  # sum over the walls of V (g . d_n) grad W
                gp_w = ti.Vector.zero(float, fl.dim)  # sum_w V_j (p_j - p0) grad W
                gv_w = ti.Vector.zero(float, fl.dim)  # sum_w V_j grad W
                pn = 0.0  # sum_w V_j (p_j - p0) W
                pd = 0.0  # sum_w V_j W
                pdw = 0.0  # the walls' share of the support
                pda = 0.0  # sum_air V_j W
                for k in range(fl.grid.nbr_count[i]):
                    j = fl.grid.nbr[i, k]
                    sj = fl.s[j]
                    rij = operators.rel(xi, fl._pos(sj), fl.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * h * h:
                        continue
                    r = ti.sqrt(r2)
                    kj = sj[fl.S_KIND]
                    vj = 0.0
                    dpj = 0.0
                    if ti.static(fl.coupled):  # noqa: SIM102 (compile-time if)
                        if kj == WATER:  # the pore pressure and wetness take the water at i's own place too
                            vj = sj[fl.S_M] / fl.rhof(j)
                            if ti.static(fl.partial):
                                vj /= self.nvs[j][0]
                            dpj = fl.p[j] - p0
                            wij = vj * kernels.w(r, h, fl.dim)
                            pn += dpj * wij
                            pd += wij
                    if ti.static(fl.soil_air):  # noqa: SIM102 (compile-time if)
                        if kj == AIR:  # the air's presence (its drag's weight), at i's own place too
                            pda += sj[fl.S_M] / fl.rhof(j) * kernels.w(r, h, fl.dim)
                    if ti.static(fl.drag_on):  # noqa: SIM102 (compile-time if)
                        if kj == WALL:
                            pdw += fl.vol0 * kernels.w(r, h, fl.dim)
                    if r2 == 0.0:
                        continue
                    gw = kernels.dw_dr(r, h, fl.dim) / r * rij
                    if kj == SOIL:
                        mj = sj[fl.S_M]
                        rhoj = fl.rhof(j)
                        vij = vi - fl._vel(sj)
                        pij = terms.artificial_viscosity(vij, rij, r2, h, ci, 0.5 * (rhoi + rhoj), self.alpha_s, 0.0,
                                                         fl.av_eps)
                        accs -= mj * (si_r + self.sig[j] / (rhoj * rhoj)) @ gw
                        acc -= mj * pij * gw
                    elif kj == WALL:
                        # boundary particle: the soil's own stress, extrapolated across the wall by its
                        # weight (Neumann) and along it by the stress gradient at i (solved below)
                        xw = xi - rij  # the wall particle's nearest image
                        db = fl.wdepth[j]
                        nrm = fl.normal[j]
                        dxw = xw - xi
                        dxn = dxw.dot(nrm) * nrm
                        mw = rhoi * fl.vol0
                        m_wall += fl.vol0 * gw.outer_product(dxw - dxn)
                        g_t += fl.vol0 * fl.g.dot(dxw - dxn) * gw
                        g_n += fl.vol0 * fl.g.dot(dxn) * gw
                        sw_r = si_r
                        if ti.static(not fl.no_slip):
                            # a slip wall carries no shear traction: the mirror image of the stress across
                            # the wall, R sigma R with R = I - 2 n n^T, whose shear on the wall's plane has
                            # the opposite sign (the pair sum cancels it); no-slip walls carry sigma itself
                            refl = ti.Matrix.identity(float, fl.dim) - 2.0 * nrm.outer_product(nrm)
                            sw_r = refl @ si_r @ refl
                        accs -= mw * (si_r + sw_r) @ gw
                        beta = walls.boundary_beta(db, rij.dot(nrm) - db, fl.beta_max)
                        vij = walls.boundary_relative_velocity(vi - fl.v[j], nrm, beta, fl.no_slip)
                        pij = terms.artificial_viscosity(vij, rij, r2, h, ci, rhoi, self.alpha_s, 0.0, fl.av_eps)
                        acc -= mw * pij * gw
                    elif kj == WATER:  # noqa: SIM102 (compile-time if)
                        if ti.static(fl.coupled and not fl.partial):  # pore_volume: the drag passes give it
                            gp_w += vj * dpj * gw
                            gv_w += vj * gw
                b_fac = 1.0  # the buoyant share of the soil's weight, (1 - phi_w rho_w / rho_s)
                pw = 0.0
                gradp = ti.Vector.zero(float, fl.dim)
                if ti.static(fl.coupled):
                    dp = -p0  # no water around: no pore pressure
                    if pd > 0.0:
                        dp = pn / pd
                    pore_i = p0 + dp
                    self.pore[i] = pore_i
                    fl.p[i] = pore_i
                    # wetness: the water's share of the support not taken by walls (1 in saturated soil
                    # beside a wall, whose wall particles take part of the kernel support)
                    pw = ti.min(pd / ti.max(1.0 - pdw, 0.5), 1.0)
                    self.phi_w[i] = pw
                    b_fac = 1.0 - pw * fl.rho_w / self.rho_g
                    # the pore pressure at a wall particle: hydrostatic across the wall (no flow through
                    # it), the gradient at i along it (the mirror image of the excess pressure): p_w - p_i
                    # = rho_w g . dx_n + G_i . dx_t, weighted by phi_w
                    if ti.static(not fl.partial):
                        gradp = gp_w - dp * gv_w + pw * fl.rho_w * g_n
                if ti.static(fl.soil_air):
                    self.phi_a[i] = ti.min(pda / ti.max(1.0 - pdw, 0.5), 1.0)
                # the walls' equilibrium gradient across their faces: the buoyant unit weight b_fac rho g
                # where water fills the pores, whose pressure the pore term extrapolates
                accs -= b_fac * g_n
                acc += walls.wall_mirror_solve(accs, m_wall, -b_fac * g_t)
                if ti.static(fl.coupled and not fl.partial):  # G_i = gradp + phi_w m_wall G_i
                    acc -= walls.wall_mirror_solve(gradp, pw * m_wall, pw * fl.rho_w * g_t) / self.rho_g
                acc -= self.damping * vi
                if ti.static(self.soil_fixed):
                    acc = ti.Vector.zero(float, fl.dim)
                held = False
                if ti.static(self.block_fixed):
                    held = self.sfix[fl.ids[i]] == 1
                if held:
                    acc = ti.Vector.zero(float, fl.dim)
                fl.a[i] = acc
                vs = vi + 0.5 * dt * (acc + self.adrag[i])  # the drag of the step before, as the fluid's
                s2 = vs.dot(vs)
                ke += 0.5 * si[fl.S_M] * s2
                ti.atomic_max(vmax, ti.sqrt(s2))
                an = acc.norm()
                if an > 0.0:
                    ti.atomic_min(h_over_a, h / an)
                if ti.static(not self.soil_fixed):  # noqa: SIM102 (compile-time if; a rigid skeleton carries no waves)
                    if not held:
                        ti.atomic_min(h_over_c, h / ci)
                val = s2 + sigi.sum() + xi.sum() + rhoi
                if ti.math.isnan(val) or ti.math.isinf(val):
                    bad += 1.0
                    ti.atomic_min(first_bad, float(fl.ids[i]))
        return ti.Vector([ke, vmax, h_over_a, h_over_c, bad, first_bad])

    @ti.func
    def _movable(self, j):
        """Whether soil particle j moves: a held skeleton (`soil.fixed`, a fixed block) takes the drag's
        reaction into its constraint."""
        fl = self.fl
        movable = True
        if ti.static(self.soil_fixed):
            movable = False
        if ti.static(self.block_fixed):  # noqa: SIM102 (compile-time if)
            if self.sfix[fl.ids[j]] == 1:
                movable = False
        return movable

    @ti.func
    def _drags(self, i):
        """Whether fluid particle i feels the soil's drag: water in a coupled scene, air where the soil has
        a conductivity for air (`soil_air`)."""
        fl = self.fl
        out = False
        if ti.static(fl.coupled):
            out = fl.kind[i] == WATER
        if ti.static(fl.soil_air):
            out = out or fl.kind[i] == AIR
        return out

    @ti.func
    def _drag_water_pass(self, dt):
        """Water side of the mixture momentum (docs/biot.md), before the drag. The water particles fill the
        whole volume, so inside the soil a water particle carries the volume-averaged velocity u = n v_f +
        (1 - n) v_s: its pore part n moves under n times the water's forces and the drag, its part (1 - n)
        moves with the soil. With the soil around it (presence phi_s, the soil's share of the support not
        taken by walls, <= 1; porosity n_bar, acceleration a_bar) and n_i = 1 - phi_s (1 - n_bar):
        A = n_i a_i + (1 - n_i) a_bar, held in `amix`; `adrag` gets A - a_i, the pair drag of eq 46-47 and
        the soil's drag share follow in `_drag_soil_pass` and `_drag_water_after_pass`. `wmix` keeps n_i, the
        weight factor f_i = phi_s / sum_soil V_j W_ij and phi_s for the pair drag. With pore water at its own
        volume (`fl.partial`) the particle carries v_f and takes no share of the soil's acceleration (A =
        a_i); n_i goes to `nvs` for the next step's fluid pass, and the pressure force on the soil's share
        (1 - n_i) of the particle's mixture volume (`gpore`, from the fluid pass) goes to the soil around it
        with the weights V_j W_ij / sum_soil V_k W_ik by which the continuity reads the soil's velocity there,
        so that the work the pore water's pressure does on the soil is the work its continuity takes from the
        soil's motion (docs/biot.md, "Pore water at its own volume")."""
        fl = self.fl
        h = fl.h0
        ti.loop_config(serialize=fl.serial)
        for m in range(fl.n if ti.static(fl.exact_grid) else fl.n_moving[None]):  # solver.moving_ids
            i = fl.moving_ids[m]
            if fl.fmask[i] == 1 and self._drags(i):
                xi = fl.xf(i)
                ai = fl.a[i]
                wsum = 0.0
                nsum = 0.0
                abar = ti.Vector.zero(float, fl.dim)
                wall = 0.0
                # soil and walls; the walls' share counts only with soil around (none: free water)
                n_sw = fl.nbr_fluid(i) if fl.nbr_walls(i) > 0 else 0
                for k in range(n_sw):
                    j = fl.grid.nbr[i, k]
                    kj = fl.kind[j]
                    rij = operators.rel(xi, fl.xf(j), fl.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * h * h:
                        continue
                    if kj == WALL:
                        wall += fl.vol0 * kernels.w(ti.sqrt(r2), h, fl.dim)
                        continue
                    rhoj = fl.rhof(j)
                    wij = kernels.w(ti.sqrt(r2), h, fl.dim) * fl.m[j] / rhoj
                    wsum += wij
                    nsum += wij * (1.0 - rhoj / self.rho_g)
                    abar += wij * fl.a[j]
                amix = ai
                wm = ti.Vector([1.0, 0.0, 0.0])
                if ti.static(fl.partial):  # the soil's share of the pressure force, over sum_soil V_j W_ij: soil j
                    gp = ti.Vector.zero(float, fl.dim)  # takes V_j W_ij times it (`_drag_soil_pass`)
                    if wsum > 0.0:
                        gp = self.gpore[i] / wsum
                    self.gpore[i] = gp
                if wsum > 0.0:
                    phi = ti.min(wsum / ti.max(1.0 - wall, 0.5), 1.0)  # the soil's share, walls aside
                    n_i = 1.0 - phi * (1.0 - nsum / wsum)
                    if ti.static(not fl.partial):  # pore water at its own volume takes no share of a_s
                        amix = n_i * ai + (1.0 - n_i) * abar / wsum
                    wm = ti.Vector([n_i, phi / wsum, phi])
                if ti.static(fl.partial):  # n_i for the next step (the soil's velocity: the last pass; it has no
                    self.nvs[i][0] = wm[0]  # weight where n_i = 1)
                self.wmix[i] = wm
                self.adrag[i] = amix - ai
                self.amix[i] = amix

    @ti.func
    def _pair_drag(self, i, j, w_ij, dt):
        """Biot drag force (eq 46-47) on water particle i from soil particle j (N; N/m in 2D); soil j feels
        its opposite. F_ij = -m_i n_i (g / k) f_i V_j W_ij q_ij with f_i = phi_s / sum_soil V_j W_ij (so
        that summed over j it is the water's -m_i n_i phi_s (g / k) (u_i - v_bar), and the soil's sum over i
        its m_j C_s phi_w (u_bar - v_j) in a uniform interior: m_i n_i g / k = rho_soil V_i C_s with n_i =
        n there). q_ij is the pair's relative velocity after the kick, implicit: q*_ij / (1 + dt lambda_ij),
        q*_ij = (u_i + dt A_i) - (v_j + dt a_j), lambda_ij = n_i (phi_s,i g / k + C_s,j phi_w,j) (the rate
        at which the drag closes u - v_s; C_s,j = 0 for a held skeleton). Both sides evaluate this
        function with the same (water, soil) arguments, so F_ij = -F_ji to rounding. w_ij is V_j W_ij (zero
        beyond the support: no force), which the caller has at hand (`_soil_weight`). An air particle i
        (`soil_air`) takes the same with the air's density for rho_w, the soil's conductivity for air k_a for
        k and the air's presence phi_a,j for phi_w,j (eq 46 with rho_f the air's)."""
        fl = self.fl
        wm = self.wmix[i]
        rhoj = fl.rhof(j)
        # the fluid's constants: water's, or the air's (its density, the soil's conductivity for air)
        c_f = self.g_over_k
        rho_f = fl.rho_w
        phi_f = self.phi_w[j]
        if ti.static(fl.soil_air):  # noqa: SIM102 (compile-time if)
            if fl.kind[i] == AIR:
                c_f = self.g_over_ka
                rho_f = fl.rho_a
                phi_f = self.phi_a[j]
        cs = 0.0
        if self._movable(j):
            cs = (1.0 - rhoj / self.rho_g) * rho_f / rhoj * c_f * phi_f
            if ti.static(fl.partial):  # the pore water's mass per mixture volume is n rho_w, not rho_w
                cs *= 1.0 - rhoj / self.rho_g
        lam = wm[0] * (wm[2] * c_f + cs)
        c = fl.m[i] * wm[0] * c_f * wm[1] * w_ij
        qs = (fl.v[i] + dt * self.amix[i]) - (fl.v[j] + dt * fl.a[j])
        return -c / (1.0 + dt * lam) * qs

    @ti.func
    def _soil_weight(self, xi, j):
        """V_j W_ij of soil particle j seen from x_i (m_j / rho_j times the kernel; 0 beyond the support)."""
        fl = self.fl
        rij = operators.rel(xi, fl.xf(j), fl.period)
        r2 = rij.dot(rij)
        w = 0.0
        if r2 < 4.0 * fl.h0 * fl.h0:
            w = kernels.w(ti.sqrt(r2), fl.h0, fl.dim) * fl.m[j] / fl.rhof(j)
        return w

    @ti.func
    def _drag_soil_pass(self, dt):
        """Soil side of the Biot drag (eq 46-47, docs/biot.md): the sum of the pair forces -F_ij of
        `_pair_drag` over the water around, per unit soil mass; zero for a held skeleton. In a uniform
        interior this is C_s phi_w (u_bar - v_s) with C_s = n rho_w / rho_soil g / k. With pore water at its
        own volume the soil's acceleration first takes the pore water's pressure: from each water particle
        around, V_i W_ij times its `gpore` (`_drag_water_pass`), so that the pair drag's implicit velocity
        sees it."""
        fl = self.fl
        ti.loop_config(serialize=fl.serial)
        for m in range(fl.n if ti.static(fl.exact_grid) else fl.n_moving[None]):  # solver.moving_ids
            i = fl.moving_ids[m]
            if fl.fmask[i] == 2:
                if ti.static(fl.partial):  # the pore water's pressure on the soil's share of its mixture volume
                    fp = ti.Vector.zero(float, fl.dim)
                    for k in range(fl.nbr_fluid(i), fl.grid.nbr_count[i]):  # water
                        j = fl.grid.nbr[i, k]
                        fp += self._soil_weight(fl.xf(j), i) * self.gpore[j]
                    if self._movable(i):
                        fl.a[i] += fp / fl.m[i]
                fsum = ti.Vector.zero(float, fl.dim)
                for k in range(fl.nbr_fluid(i), fl.grid.nbr_count[i]):  # water and air
                    j = fl.grid.nbr[i, k]
                    if self._drags(j):
                        w = self._soil_weight(fl.xf(j), i)
                        if w > 0.0:
                            fsum -= self._pair_drag(j, i, w, dt)
                if not self._movable(i):
                    fsum = ti.Vector.zero(float, fl.dim)
                self.fdrag[i] = fsum
                self.adrag[i] = fsum / fl.m[i]

    @ti.func
    def _drag_water_after_pass(self, dt):
        """Water side of the Biot drag: the pair forces F_ij of `_pair_drag` over the soil around, and the
        share (1 - n_i) that moves with the soil takes the soil's mean drag acceleration (docs/biot.md); with
        pore water at its own volume there is no such share, and `nvs` gets the soil's mean velocity after
        its next kick, v + dt (a + a_drag), for the next step's continuity.
        Also the momentum check: the sum over all particles of the drag forces `fdrag` (the soil's from
        `_drag_soil_pass`) and the largest of them (returned)."""
        fl = self.fl
        tot = ti.Vector.zero(float, fl.dim)
        big = 0.0
        ti.loop_config(serialize=fl.serial)
        for m in range(fl.n if ti.static(fl.exact_grid) else fl.n_moving[None]):  # solver.moving_ids
            i = fl.moving_ids[m]
            if fl.fmask[i] == 2:
                f = self.fdrag[i]
                tot += f
                ti.atomic_max(big, f.norm())
            if fl.fmask[i] == 1 and self._drags(i):
                fsum = ti.Vector.zero(float, fl.dim)
                wsum = 0.0
                dbar = ti.Vector.zero(float, fl.dim)
                vnext = ti.Vector.zero(float, fl.dim)
                xi = fl.xf(i)
                for k in range(fl.nbr_walls(i)):  # soil
                    j = fl.grid.nbr[i, k]
                    wij = self._soil_weight(xi, j)
                    if wij > 0.0:
                        fsum += self._pair_drag(i, j, wij, dt)
                        wsum += wij
                        dbar += wij * self.adrag[j]
                        if ti.static(fl.partial):  # the soil's velocity after its next kick
                            vnext += wij * (fl.v[j] + dt * (fl.a[j] + self.adrag[j]))
                ad = self.adrag[i] + fsum / fl.m[i]
                if ti.static(not fl.partial):  # noqa: SIM102
                    if wsum > 0.0:
                        ad += (1.0 - self.wmix[i][0]) * dbar / wsum
                if ti.static(fl.partial):  # noqa: SIM102
                    if wsum > 0.0:
                        for d in ti.static(range(fl.dim)):
                            self.nvs[i][1 + d] = vnext[d] / wsum
                self.fdrag[i] = fsum
                self.adrag[i] = ad
                tot += fsum
                ti.atomic_max(big, fsum.norm())
        return ti.Vector([tot[d] for d in ti.static(range(fl.dim))] + [big])

    # ------------------------------------------------------------------ host side
    def after_passes(self, red):
        """The host's part after the pair kernel: `red` the soil's reductions (`passes`)."""
        fl = self.fl
        r = red[:_NRED_S].copy()
        self.red_s = r
        if r[4] > 0:
            raise guard.non_finite_error(fl.step_count, fl.time, int(r[4]), int(r[5]),
                                         "soil position, velocity, density or stress")
        fl.last["kinetic_energy"] += float(r[0])
        fl.last["max_speed"] = max(fl.last["max_speed"], float(r[1]))
        if fl.drag_on:
            r = red[_NRED_S:]
            fl.last["drag_sum"] = float(np.linalg.norm(r[:-1]))
            fl.last["drag_max"] = float(r[-1])

    def output(self, order) -> dict:
        """Frame fields of the soil (zero for other particles): effective stress (compression positive),
        mean and shear stress of eq 11-13, accumulated plastic shear strain, ever yielded."""
        fl = self.fl
        n = fl.n
        sig = self.sig.to_numpy()[:n][order]
        kind = fl.kind.to_numpy()[order]
        sig[kind != SOIL] = 0.0
        d = fl.dim
        p = np.trace(sig, axis1=1, axis2=2) / d
        dev = sig - p[:, None, None] * np.eye(d)
        tau = np.sqrt(0.5 * np.einsum("nij,nij->n", dev, dev))
        eps_p = self.eps_p.to_numpy()[:n][order]
        return {"effective_stress": sig, "mean_stress": p, "shear_stress": tau, "plastic_strain": eps_p,
                "yielded": eps_p > 0.0}
