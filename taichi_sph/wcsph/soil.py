"""Soil of mode wcsph_biot (seed 002 sections 2.2-2.4 (2)): elastic-perfectly-plastic effective stress.

Conventions: stress sigma is the effective stress, **compression positive** as in the seed (eq 10-11),
so eq 35 reads like eq 34 with sigma in place of p I. Velocity gradient L_ab = d v_a / d x_b from
sum_j V_j (v_j - v_i) (x) grad_i W_ij; the seed's strain rate (eq 17, 37) is its negative symmetric part
eps_dot = -(L + L^T) / 2 (compression positive), and its spin W = (L - L^T) / 2 (eq 19, 38 up to sign).

Mean stress and shear stress in d dimensions: p = tr(sigma) / d (in 2D the seed's eq 12), s = sigma - p I
(eq 11, 13), tau = sqrt(s : s / 2) (in 2D the radius of Mohr's circle, in 3D sqrt(J2)).

Elasticity (eq 42-44): E = E0 (max(p, p_floor) / p0)^m with the floor documented in the schema, G =
E / (2 (1 + nu)), and the d-dimensional bulk modulus K_d with dp = K_d tr(eps_dot) dt:
- 2D **plane strain** (eps_zz = 0): K_2 = lambda + G = E / (2 (1 + nu) (1 - 2 nu)). The seed's eq 43
  writes B = E / (2 (1 - nu)), which is the plane-stress value; plane strain is the state of a long
  levee or a flume section, so the plane-strain modulus is used.
- 3D: K_3 = E / (3 (1 - 2 nu)).

Jaumann rate (eq 45): sigma_dot = 2 G eps_dot_d + K_d tr(eps_dot) I + W sigma - sigma W (the objective
rotation of the stress with the material; for a rigid rotation the principal stresses keep their values).

Plasticity (yield surface, docs/biot.md): tau_f = max(p sin(phi) + c cos(phi), 0), phi the Mohr-Coulomb
friction angle and c the cohesion;
- 2D: tau is the radius of the in-plane Mohr circle and p its centre, so tau = tau_f is Mohr-Coulomb in
  plane strain exactly (the circle touches the line tau_n = c + sigma_n tan(phi));
- 3D: tau = sqrt(J2) and p = I1 / 3: the Drucker-Prager cone that coincides with Mohr-Coulomb in plane
  strain for this flow rule (deviatoric radial return, no plastic volume change: at plane-strain failure
  s_zz = 0, so p is the in-plane mean and sqrt(J2) the in-plane radius); it circumscribes the
  Mohr-Coulomb pyramid in triaxial extension and lies inside it in triaxial compression.
The seed writes tau_f = p tan(phi) (section 2.4 (2), no cohesion) on the same tau and p: Mohr-Coulomb with
sin(phi) = tan(phi_seed); a config's `tan_phi` is mapped so (schema.WCSPHSoil.friction_angle_deg).
If tau > tau_f the deviator is scaled back radially to tau_f (return mapping, no dilatancy, the seed's
phi_d = 0); below the tension cut-off (p < -t) the stress is set to -t I. The plastic shear strain
increment (tau - tau_f) / G is accumulated.
"""

import math

import numpy as np
import taichi as ti


def bulk_modulus_factor(dim: int, nu: float) -> float:
    """K_d / E: 2D plane strain 1 / (2 (1 + nu) (1 - 2 nu)), 3D 1 / (3 (1 - 2 nu))."""
    return 1.0 / (2.0 * (1.0 + nu) * (1.0 - 2.0 * nu)) if dim == 2 else 1.0 / (3.0 * (1.0 - 2.0 * nu))


def p_wave_factor(dim: int, nu: float) -> float:
    """M / E with M = K_d + 2 G (1 - 1 / d) the P-wave modulus (plane strain in 2D: lambda + 2 G)."""
    return bulk_modulus_factor(dim, nu) + (1.0 - 1.0 / dim) / (1.0 + nu)


def youngs_modulus_np(p, e0, p_ref, m, p_floor):
    """E = E0 (max(p, p_floor) / p0)^m (eq 42), numpy."""
    return e0 * (np.maximum(p, p_floor) / p_ref) ** m


@ti.func
def youngs_modulus(p, e0, p_ref, m, p_floor):
    """E = E0 (max(p, p_floor) / p0)^m (eq 42)."""
    return e0 * (ti.max(p, p_floor) / p_ref) ** m


@ti.func
def mean_and_shear(sig, dim: ti.template()):
    """p = tr(sigma) / d, s = sigma - p I, tau = sqrt(s : s / 2) (eq 11-13)."""
    p = sig.trace() / dim
    s = sig - p * ti.Matrix.identity(float, dim)
    tau = ti.sqrt(0.5 * (s * s).sum())
    return p, s, tau


@ti.func
def stress_update(sig, L, dt, e0, p_ref, m, p_floor, nu, k_fac, sin_phi, c_cos, t_cut, dim: ti.template(),
                  sin_psi=0.0, dilatant: ti.template() = False):
    """One explicit step of eq 42-45 with the return to the yield surface tau_f = p sin(phi) + c cos(phi).
    `L` the velocity gradient d v_a / d x_b, `k_fac` = K_d / E, `sin_phi` = sin(phi), `c_cos` = c cos(phi).
    Plastic flow along the potential tau - p sin(psi) (compression positive): with `dilatant` (psi > 0) the
    plastic strain d lambda (s / (2 tau) - sin(psi) I / d) dilates the soil, so the return raises p by
    K d lambda sin(psi) while it lowers tau by G d lambda, d lambda = (tau - tau_f) / (G + K sin(phi)
    sin(psi)); without it the return is radial in the deviatoric plane (psi = 0).
    Returns (sigma^{n+1}, plastic shear strain increment, E used)."""
    eye = ti.Matrix.identity(float, dim)
    p0, _, _ = mean_and_shear(sig, dim)
    e = youngs_modulus(p0, e0, p_ref, m, p_floor)
    g = e / (2.0 * (1.0 + nu))
    eps = -0.5 * (L + L.transpose())  # eq 37, compression positive
    spin = 0.5 * (L - L.transpose())
    tr = eps.trace()
    eps_d = eps - tr / dim * eye
    rate = 2.0 * g * eps_d + k_fac * e * tr * eye + spin @ sig - sig @ spin
    trial = sig + dt * rate
    p, s, tau = mean_and_shear(trial, dim)
    dgam = 0.0
    out = trial
    if p < -t_cut:
        out = -t_cut * eye
        dgam = tau / g
    else:
        tau_f = ti.max(p * sin_phi + c_cos, 0.0)
        if tau > tau_f:
            if ti.static(dilatant):
                kb = k_fac * e
                dlam = (tau - tau_f) / (g + kb * sin_phi * sin_psi)
                out = (p + kb * dlam * sin_psi) * eye + s * (ti.max(tau - g * dlam, 0.0) / tau)
                dgam = dlam
            else:
                out = p * eye + s * (tau_f / tau)
                dgam = (tau - tau_f) / g
    return out, dgam, e


def yield_constants(friction_angle_deg: float, cohesion: float) -> tuple[float, float]:
    """(sin(phi), c cos(phi)) of the yield surface tau_f = p sin(phi) + c cos(phi)."""
    phi = math.radians(friction_angle_deg)
    return math.sin(phi), cohesion * math.cos(phi)


def geostatic_stress(sigma_v: np.ndarray, k0: float, dim: int) -> np.ndarray:
    """K0 start state: sigma_v on the vertical axis, K0 sigma_v on the others, no shear; (N, d, d)."""
    n = len(sigma_v)
    sig = np.zeros((n, dim, dim))
    for a in range(dim - 1):
        sig[:, a, a] = k0 * sigma_v
    sig[:, dim - 1, dim - 1] = sigma_v
    return sig
