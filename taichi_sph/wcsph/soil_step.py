"""Soil passes of mode wcsph_biot (seed 002 sections 2.3-2.5), mixed into WCSPHSolver.

Soil particles (kind 2) are their own set overlapping the fluid sets (the seed's layers, fig 3); the
fluid pair loops skip them. Per step, after the fluid density pass and force pass of solver.py:

1. stress pass (`_k_soil_stress`) at x^{n+1} with v^{n+1/2}: velocity gradient from soil neighbours and
   walls (virtual velocity of eq 50-51), strain and spin rates (eq 37-38), density by eq 48, effective
   stress by eq 42-45 (soil.py), pore pressure p_i = sum_w V_j p_j W_ij / sum_w V_j W_ij from the water
   (eq 5, Shepard-normalised).
2. force pass (`_k_soil_forces`): eq 35 with eq 36, gravity, the pore-pressure force -grad p / rho_s
   (per unit soil mass, the (1 - n) grad p of the mixture theory over the soil's (1 - n) rho_s) and an
   optional damping.
3. drag pass (`_k_drag`): eq 46 between soil and water, implicit (docs/biot.md), written to `adrag`
   which the next kick adds to the acceleration.
"""

import math

import numpy as np
import taichi as ti

from .. import guard
from ..scene import SOIL, WALL, WATER
from ..sph import kernels, operators
from . import soil, terms

_NRED_S = 6


class SoilStep:
    """Soil state and passes; needs the attributes WCSPHSolver sets before calling `_soil_setup`."""

    def _soil_setup(self, cfg, scene):
        sp = cfg.wcsph.soil
        self.n_soil = scene.count(SOIL)
        self.has_soil = self.n_soil > 0
        self.coupled = self.has_soil and self.n_water > 0  # pore pressure and drag
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
        self.tan_phi = sp.tan_phi
        self.coh_s = sp.cohesion
        if sp.tension_cutoff is not None:
            self.t_cut = sp.tension_cutoff
        else:
            self.t_cut = sp.cohesion / sp.tan_phi if sp.tan_phi > 0 else 0.0
        self.alpha_s = sp.alpha
        self.g_over_k = self.g_abs / sp.permeability
        self.damping = sp.damping

    def _soil_fields(self, n):
        ns = n if self.has_soil else 1
        dim = self.dim
        self.sig = ti.Matrix.field(dim, dim, float, ns)  # effective stress, compression positive
        self.eps_p = ti.field(float, ns)  # accumulated plastic shear strain
        self.pore = ti.field(float, ns)  # pore pressure at soil particles (gauge)
        self.phi_w = ti.field(float, ns)  # water presence sum_w V_j W_ij at soil particles
        self.adrag = ti.Vector.field(dim, float, ns)  # drag acceleration of eq 46, added by the kick
        self.red_soil = ti.Vector.field(_NRED_S, float, ())
        self.red_s = np.array([0.0, 0.0, 1e30, 1e30, 0.0, 0.0])
        if self.has_soil:
            self.particle_fields += [self.sig, self.eps_p, self.pore, self.phi_w, self.adrag]
            self.adrag.fill(0.0)

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _k_soil_stress(self, dt: float):
        """Strain and spin rates (eq 37-38), density (eq 48), stress (eq 42-45), pore pressure (eq 5)."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.fmask[i] == 2:
                si = self.s[i]
                xi = self._pos(si)
                vi = self._vel(si)
                rhoi = si[self.S_RHO]
                h = self.h0
                L = ti.Matrix.zero(float, self.dim, self.dim)
                pn = 0.0
                pd = 0.0
                for k in range(self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    sj = self.s[j]
                    rij = operators.rel(xi, self._pos(sj), self.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * h * h:
                        continue
                    kj = sj[self.S_KIND]
                    if kj == WATER:
                        if ti.static(self.coupled):
                            wij = kernels.w(ti.sqrt(r2), h, self.dim)
                            vj = sj[self.S_M] / self.rho[j]
                            pn += vj * self.p[j] * wij
                            pd += vj * wij
                        continue
                    if r2 == 0.0:
                        continue
                    r = ti.sqrt(r2)
                    gw = kernels.dw_dr(r, h, self.dim) / r * rij
                    if kj == SOIL:
                        L += sj[self.S_M] / sj[self.S_RHO] * (self._vel(sj) - vi).outer_product(gw)
                    elif kj == WALL:
                        db = self.wdepth[j]
                        nrm = self.normal[j]
                        beta = terms.boundary_beta(db, rij.dot(nrm) - db, self.beta_max)
                        vij = terms.boundary_relative_velocity(vi, nrm, beta, self.no_slip)
                        L -= self.vol0 * vij.outer_product(gw)
                rho = rhoi * (1.0 - L.trace() * dt)
                sig, dgam, _e = soil.stress_update(self.sig[i], L, dt, self.e0, self.p_ref, self.m_exp, self.p_floor,
                                                   self.nu_s, self.k_fac, self.tan_phi, self.coh_s, self.t_cut,
                                                   self.dim)
                self.sig[i] = sig
                self.eps_p[i] += dgam
                self.rho[i] = rho
                self.q[i][self.Q_RHO] = rho
                pore = 0.0
                if pd > 0.0:
                    pore = pn / pd
                self.pore[i] = pore
                self.p[i] = pore
                self.phi_w[i] = ti.min(pd, 1.0)

    @ti.kernel
    def _k_soil_forces(self, dt: float):
        """Eq 35 with eq 36, gravity, pore-pressure force, damping; reductions: kinetic energy, max speed,
        min h/|a|, min h/c, non-finite count, first bad id."""
        ke = 0.0
        vmax = 0.0
        h_over_a = 1.0e30
        h_over_c = 1.0e30
        bad = 0.0
        first_bad = 2.0e9
        h = self.h0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            if self.fmask[i] == 2:
                si = self.s[i]
                xi = self._pos(si)
                vi = self._vel(si)
                rhoi = self.rho[i]
                sigi = self.sig[i]
                si_r = sigi / (rhoi * rhoi)
                p_i, _s, _t = soil.mean_and_shear(sigi, self.dim)
                ci = ti.sqrt(self.m_fac * soil.youngs_modulus(p_i, self.e0, self.p_ref, self.m_exp, self.p_floor) / rhoi)
                pore_i = self.pore[i]
                acc = self.g
                gradp = ti.Vector.zero(float, self.dim)
                for k in range(self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    sj = self.s[j]
                    rij = operators.rel(xi, self._pos(sj), self.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * h * h or r2 == 0.0:
                        continue
                    r = ti.sqrt(r2)
                    gw = kernels.dw_dr(r, h, self.dim) / r * rij
                    kj = sj[self.S_KIND]
                    if kj == SOIL:
                        mj = sj[self.S_M]
                        rhoj = self.rho[j]
                        vij = vi - self._vel(sj)
                        pij = terms.artificial_viscosity(vij, rij, r2, h, ci, 0.5 * (rhoi + rhoj), self.alpha_s, 0.0,
                                                         self.av_eps)
                        acc -= mj * ((si_r + self.sig[j] / (rhoj * rhoj)) @ gw + pij * gw)
                    elif kj == WALL:
                        # boundary particle: the soil's own stress, extrapolated by its weight (Neumann)
                        xw = xi - rij  # the wall particle's nearest image
                        dsig = rhoi * self.g.dot(xw - xi)
                        mw = rhoi * self.vol0
                        acc -= mw * (2.0 * si_r + dsig / (rhoi * rhoi) * ti.Matrix.identity(float, self.dim)) @ gw
                        db = self.wdepth[j]
                        nrm = self.normal[j]
                        beta = terms.boundary_beta(db, rij.dot(nrm) - db, self.beta_max)
                        vij = terms.boundary_relative_velocity(vi, nrm, beta, self.no_slip)
                        pij = terms.artificial_viscosity(vij, rij, r2, h, ci, rhoi, self.alpha_s, 0.0, self.av_eps)
                        acc -= mw * pij * gw
                        if ti.static(self.coupled):
                            gradp += self.phi_w[i] * self.vol0 * self.rho_w * self.g.dot(xw - xi) * gw
                    elif kj == WATER:  # noqa: SIM102 (compile-time if)
                        if ti.static(self.coupled):
                            gradp += sj[self.S_M] / self.rho[j] * (self.p[j] - pore_i) * gw
                if ti.static(self.coupled):
                    acc -= gradp / self.rho_g
                acc -= self.damping * vi
                self.a[i] = acc
                vs = vi + 0.5 * dt * acc
                s2 = vs.dot(vs)
                ke += 0.5 * si[self.S_M] * s2
                ti.atomic_max(vmax, ti.sqrt(s2))
                an = acc.norm()
                if an > 0.0:
                    ti.atomic_min(h_over_a, h / an)
                ti.atomic_min(h_over_c, h / ci)
                val = s2 + sigi.sum() + xi.sum() + rhoi
                if ti.math.isnan(val) or ti.math.isinf(val):
                    bad += 1.0
                    ti.atomic_min(first_bad, float(self.ids[i]))
        self.red_soil[None] = ti.Vector([ke, vmax, h_over_a, h_over_c, bad, first_bad])

    @ti.kernel
    def _k_drag(self, dt: float):
        """Biot drag of eq 46-47, implicit and local (docs/biot.md). With the velocities each particle
        would have at the next kick without drag, u* (water) and v* (soil), and the other phase's
        kernel average around it, the relative velocity after the kick is w = (u* - v*) / (1 + dt (C_w +
        C_s)), C_w = g / k, C_s = n rho_w / rho_soil g / k (the water layer's and the soil's drag rates
        per unit mass); the drag accelerations are -C_w w on water and +C_s w on soil, scaled by how much
        of the other phase is present."""
        h = self.h0
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            ki = self.kind[i]
            if self.fmask[i] >= 1 and (ki == SOIL or ki == WATER):
                xi = self.x[i]
                ui = self.v[i] + dt * self.a[i]
                other = WATER
                if ki == WATER:
                    other = SOIL
                wsum = 0.0
                ubar = ti.Vector.zero(float, self.dim)
                csum = 0.0
                for k in range(self.grid.nbr_count[i]):
                    j = self.grid.nbr[i, k]
                    if self.kind[j] != other:
                        continue
                    rij = operators.rel(xi, self.x[j], self.period)
                    r2 = rij.dot(rij)
                    if r2 >= 4.0 * h * h:
                        continue
                    wij = kernels.w(ti.sqrt(r2), h, self.dim) * self.m[j] / self.rho[j]
                    wsum += wij
                    ubar += wij * (self.v[j] + dt * self.a[j])
                    if other == SOIL:
                        csum += wij * (1.0 - self.rho[j] / self.rho_g) * self.rho_w / self.rho[j]
                ad = ti.Vector.zero(float, self.dim)
                if wsum > 0.0:
                    phi = ti.min(wsum, 1.0)
                    ubar /= wsum
                    if ki == WATER:
                        cw = self.g_over_k * phi
                        cs = csum / wsum * self.g_over_k
                        w = (ui - ubar) / (1.0 + dt * (cw + cs))
                        ad = -cw * w
                    else:
                        cw = self.g_over_k
                        cs = (1.0 - self.rho[i] / self.rho_g) * self.rho_w / self.rho[i] * self.g_over_k * phi
                        w = (ubar - ui) / (1.0 + dt * (cw + cs))
                        ad = cs * w
                self.adrag[i] = ad

    # ------------------------------------------------------------------ host side
    def _soil_stress(self, dt: float):
        self._k_soil_stress(dt)

    def _soil_forces(self, dt: float):
        self._k_soil_forces(dt)
        r = self.red_soil[None].to_numpy()
        self.red_s = r
        if r[4] > 0:
            raise guard.non_finite_error(self.step_count, self.time, int(r[4]), int(r[5]),
                                         "soil position, velocity, density or stress")
        self.last["kinetic_energy"] += float(r[0])
        self.last["max_speed"] = max(self.last["max_speed"], float(r[1]))
        if self.coupled:
            self._k_drag(dt)

    def _soil_output(self, order) -> dict:
        """Frame fields of the soil (zero for other particles): effective stress (compression positive),
        mean and shear stress of eq 11-13, accumulated plastic shear strain, ever yielded."""
        n = self.n
        sig = self.sig.to_numpy()[:n][order]
        kind = self.kind.to_numpy()[order]
        sig[kind != SOIL] = 0.0
        d = self.dim
        p = np.trace(sig, axis1=1, axis2=2) / d
        dev = sig - p[:, None, None] * np.eye(d)
        tau = np.sqrt(0.5 * np.einsum("nij,nij->n", dev, dev))
        eps_p = self.eps_p.to_numpy()[:n][order]
        return {"effective_stress": sig, "mean_stress": p, "shear_stress": tau, "plastic_strain": eps_p,
                "yielded": eps_p > 0.0}

    def soil_sound_speed(self, p: float) -> float:
        """P-wave speed of the soil at mean effective stress p (m/s)."""
        e = soil.youngs_modulus_np(p, self.e0, self.p_ref, self.m_exp, self.p_floor)
        return math.sqrt(self.m_fac * float(e) / self.rho_sl)
