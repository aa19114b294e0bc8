"""Terms of mode isph (seed 000 section 3), each a small ti.func named for what it computes and citing its
equation; isph/solver.py's kernels loop over the neighbours and call them. The coefficients of eq 9a, 9c
and 9d (inertia, linear and quadratic drag) are in porosity.py with the porosity they depend on.

Notation: i the particle, j a neighbour, rij = x_i - x_j, gw = grad_i W_ij, F_ij = rij . gw / (r^2 + eta^2)
(operators.laplacian_weight), m mass, rho_bar = eps rho_w (eq 33), vD the Darcy velocity.
"""

import taichi as ti

from ..sph import operators
from . import porosity


@ti.func
def effective_viscosity(nu, nu_t, eps):
    """nu_E = (nu_w + nu_T) / eps (eq 9b), as nu_w / eps + nu_T / eps."""
    return nu / eps + nu_t / eps


@ti.func
def viscous_pair(m_j, rb_i, nu_i, rb_j, nu_j, f_ij, v_i, v_j):
    """Pair term of the variable-viscosity Laplacian nu_E lap(vD) (eq 22), pairwise mean of rho_bar nu_E."""
    return operators.variable_laplacian_pair(m_j, rb_i, nu_i, rb_j, nu_j, f_ij) * (v_i - v_j)


@ti.func
def drag_factor(eps, nu, d50, speed, c, alpha_c, beta_c):
    """D = 1 + c (a + b |vD|) with c = eps dt / Cr (eq 9c-d in eq 19, implicit): the factor by which the
    drag divides the whole projection, vD(n+1) = (vD + c (g / eps + nu_E lap vD) - c grad P / rho_bar) / D
    (a deviation from the seed's explicit drag, docs/isph.md)."""
    a = porosity.linear_drag(eps, nu, d50, alpha_c)
    b = porosity.quadratic_drag(eps, d50, beta_c)
    return 1.0 + c * (a + b * speed)


@ti.func
def predicted_velocity(v, c, g, eps, lap, drag):
    """vD* = (vD + c (g / eps + nu_E lap vD)) / D (eq 19 with the implicit drag D)."""
    return (v + c * (g / eps + lap)) / drag


@ti.func
def divergence_pair(m_j, v_i, v_j, gw):
    """Pair term of div(vD)_i rho_bar_i = sum_j m_j (vD_j - vD_i) . gw (eq 23)."""
    return m_j * (v_j - v_i).dot(gw)


@ti.func
def ppe_pair(m_j, rb_i, k_i, rb_j, k_j, f_ij):
    """Off-diagonal magnitude K_ij of the PPE row of i: div(k grad P)_i = -sum_j K_ij (P_i - P_j) (eq 24
    with k = c / (D rho_bar), pairwise mean of rho_bar k); K_ij > 0."""
    return -operators.variable_laplacian_pair(m_j, rb_i, k_i, rb_j, k_j, f_ij)


@ti.func
def density_stabilisation(alpha, eps, rho_ref, rho_n, dt):
    """Eq 31's stabilisation in the symmetric form of the PPE: alpha eps (rho_ref - <rho>) / (rho_ref dt),
    rho_ref the rest density (rho_bar, or the packing's own in the ground; docs/isph.md)."""
    return alpha * eps * (rho_ref - rho_n) / (rho_ref * dt)


@ti.func
def pressure_gradient_difference(m_j, rb_j, p_i, p_j, gw):
    """Pair term of grad P (eq 12, difference form): m_j / rho_bar_j (P_j - P_i) gw."""
    return m_j / rb_j * (p_j - p_i) * gw


@ti.func
def pressure_gradient_symmetric(m_j, rb_i, rb_j, p_i, p_j, gw):
    """Pair term of grad P / rho_bar_i (eq 13, symmetric form): m_j (P_j / rho_bar_j^2 + P_i / rho_bar_i^2) gw."""
    return m_j * (p_j / (rb_j * rb_j) + p_i / (rb_i * rb_i)) * gw


@ti.func
def moment_pair(v_j, rij, gw):
    """Pair term of the moment matrix M_i = sum_j V_j (x_j - x_i) (x) gw, whose inverse corrects the kernel
    gradient (L_i of eq 12 with correction)."""
    return v_j * (-rij).outer_product(gw)


@ti.func
def smagorinsky_viscosity(cs_delta2, grad_v):
    """nu_T = (Cs Delta)^2 |S| (eq 3), S the strain rate of the velocity gradient grad_v, |S| = sqrt(2 S:S)."""
    S = 0.5 * (grad_v + grad_v.transpose())
    s2 = 0.0
    for a, c in ti.static(ti.ndrange(grad_v.n, grad_v.m)):
        s2 += S[a, c] * S[a, c]
    return cs_delta2 * ti.sqrt(2.0 * s2)


@ti.func
def collision_impulse(v_i, v_j, e_ji, restitution):
    """Velocity change of particle i in a near-contact collision with particle j of equal mass, e_ji the
    unit vector from i to j, and whether they collide: an approaching pair loses (1 + e) / 2 of its relative
    normal velocity on each side; a separating pair nothing."""
    dv = ti.Vector.zero(float, v_i.n)
    hit = 0
    vrel = (v_i - v_j).dot(e_ji)
    if vrel > 0.0:
        dv = -0.5 * (1.0 + restitution) * vrel * e_ji
        hit = 1
    return dv, hit
