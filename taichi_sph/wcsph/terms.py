"""Pair terms of mode wcsph_biot (seed 002 sections 2.3 and 2.6), each a small ti.func citing its equation.

Notation: i the particle, j a neighbour, rij = x_i - x_j, vij = v_i - v_j, gw = grad_i W_ij (pointing
from i towards j), m mass, V = m / rho volume, p gauge pressure. The Morris viscous term of eq 34 is
`variable_laplacian_pair` of `taichi_sph.sph.operators` with rho nu = mu.
"""

import taichi as ti


@ti.func
def pressure_same_material(m_j, pr_i, pr_j, gw):
    """Pressure acceleration of eq 34 between particles of one material, -m_j (p_i/rho_i^2 + p_j/rho_j^2) gw,
    with pr = p / rho^2 of each particle."""
    return -m_j * (pr_i + pr_j) * gw


@ti.func
def pressure_interface(m_i, v_i, v_j, p_i, p_j, gw):
    """Pressure acceleration between particles of different materials (water-air), in volume form:
    -(V_i^2 + V_j^2) / m_i (p_i + p_j) / 2 gw. Pair forces stay equal and opposite, and between particles
    of equal volume and density this is eq 34; eq 34's m_j / rho_j^2 weighting would instead let a water
    particle push an air particle with water's mass over air's density squared. Each side feels the
    other's pressure in full, so neither can slip into the other."""
    return -(v_i * v_i + v_j * v_j) / m_i * 0.5 * (p_i + p_j) * gw


@ti.func
def artificial_viscosity(vij, rij, r2, h_ij, c_ij, rho_ij, alpha, beta, eps):
    """Monaghan artificial viscous pressure Pi_ij of eq 36 (zero unless the pair approaches):
    mu_ij = h_ij vij . rij / (r^2 + eps h_ij^2), Pi_ij = (-alpha c_ij mu_ij + beta mu_ij^2) / rho_ij;
    its acceleration is -m_j Pi_ij gw."""
    vr = vij.dot(rij)
    pi_ij = 0.0
    if vr < 0.0:
        mu = h_ij * vr / (r2 + eps * h_ij * h_ij)
        pi_ij = (-alpha * c_ij * mu + beta * mu * mu) / rho_ij
    return pi_ij


@ti.func
def cohesion(coef, m_j, gw):
    """Pseudo surface tension eq 54: 2 (a / m_i^2) m_j grad_i W_ij with a / m_i^2 = coef = P_c / rho0^2;
    pulls particles of a material towards its bulk."""
    return 2.0 * coef * m_j * gw


@ti.func
def xsph(m_j, rho_i, rho_j, vij, w_ij):
    """XSPH correction eq 53 (Monaghan's form): -(m_j / rho_ij) vij W_ij, rho_ij = (rho_i + rho_j) / 2;
    multiplied by eps_XSPH and added to the velocity a particle moves with; summed over neighbours of the
    particle's own material (docs/wcsph.md, XSPH)."""
    return -m_j / (0.5 * (rho_i + rho_j)) * vij * w_ij
