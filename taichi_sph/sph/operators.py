"""SPH pair operators shared by both modes (Laplacian pair factors, periodic pair differences), each a
small ti.func citing its equation in seed 000; what a particle sees at a wall is in walls.py.

Notation: i the particle, j a neighbour, rij = x_i - x_j, F_ij = rij . grad W_ij / (r^2 + eta^2)
(< 0), V_j = m_j / rho_bar_j, rho_bar = eps rho_w (eq 33).
"""

import taichi as ti

from . import kernels


@ti.func
def laplacian_weight(r, h, eta2, dim: ti.template()):
    """F_ij = rij . grad W_ij / (r^2 + eta^2) = r dW/dr / (r^2 + eta^2), the pair factor of eq 14, 22, 24."""
    return kernels.dw_dr(r, h, dim) * r / (r * r + eta2)


@ti.func
def variable_laplacian_pair(m_j, rb_i, q_i, rb_j, q_j, f_ij):
    """Pair coefficient of the variable-coefficient Laplacian eq 22 / eq 24:
    m_j (rho_bar_i q_i + rho_bar_j q_j) / (rho_bar_i rho_bar_j) F_ij, so that
    div(q grad phi)_i = sum_j coef_ij (phi_i - phi_j)."""
    return m_j * (rb_i * q_i + rb_j * q_j) / (rb_i * rb_j) * f_ij


@ti.func
def rel(xi, xj, period: ti.template()):
    """Pair displacement x_i - x_j, by the minimum image along periodic axes. `period` holds the period L
    of each axis, 0.0 where the axis is not periodic (a Python tuple: the wrap compiles only for the
    periodic axes, a scene without them compiles the plain difference)."""
    d = xi - xj
    for a in ti.static(range(len(period))):
        if ti.static(period[a] > 0.0):
            d[a] -= ti.static(period[a]) * ti.floor(d[a] / ti.static(period[a]) + 0.5)
    return d


@ti.func
def wrap(x, period: ti.template()):
    """Position x brought back into [0, L) along each periodic axis (others unchanged)."""
    y = x
    for a in ti.static(range(len(period))):
        if ti.static(period[a] > 0.0):
            L = ti.static(period[a])
            y[a] -= L * ti.floor(y[a] / L)
            if y[a] >= L:  # x = -tiny rounds to L
                y[a] -= L
    return y
