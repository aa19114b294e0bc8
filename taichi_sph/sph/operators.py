"""SPH pair operators shared by both modes (Laplacian pair factors, wall mirror velocity and pressure),
each a small ti.func citing its equation in seed 000.

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
def mirror_velocity(v_i, v_w, n_w, no_slip: ti.template()):
    """Velocity a wall particle (moving at v_w, zero for fixed walls) takes as seen from fluid particle i
    (virtual-marker idea of the seed, evaluated at i itself): relative to the wall, no-slip reverses the
    whole velocity, slip only its normal component."""
    u = v_i - v_w
    out = -u
    if ti.static(not no_slip):
        out = u - 2.0 * u.dot(n_w) * n_w
    return v_w + out


@ti.func
def wall_mirror_solve(s, m_wall, along_equilibrium):
    """Gradient-like sum G = s + m_wall G of a particle whose wall neighbours carry the mirror image of
    the field along their faces (docs/wcsph.md, "Walls"): G = (I - m_wall)^-1 s, m_wall = sum over walls
    V grad W (x) d_t. Where I - m_wall is near singular (det < 0.25), the walls take the equilibrium
    gradient along their faces too: s + along_equilibrium, the same terms with that gradient."""
    a = ti.Matrix.identity(float, s.n) - m_wall
    out = s + along_equilibrium
    if ti.abs(a.determinant()) > 0.25:
        out = a.inverse() @ s
    return out


@ti.func
def wall_pressure(p_i, rho_w, g, x_w, x_i):
    """Wall pressure seen from fluid particle i: Neumann condition with hydrostatic correction,
    P_w = P_i + rho_w g . (x_w - x_i)."""
    return p_i + rho_w * g.dot(x_w - x_i)


@ti.func
def wall_pressure_along_face(p_i, rho_w, g, grad_t, n_w, d):
    """Wall pressure seen from fluid particle i, d = x_w - x_i, n_w the wall's unit normal (mirror-point
    idea of the seed's virtual markers): the hydrostatic Neumann condition dP/dn = rho_w g . n across
    the wall, and along its face the fluid's own pressure gradient grad_t (not gravity's):
    P_w = P_i + rho_w (g . n_w)(n_w . d) + grad_t . (d - (n_w . d) n_w). Water at rest has grad_t =
    rho_w g, and this is P_i + rho_w g . d; a drop sliding down a wall has grad_t ~ 0, and the wall
    carries no hydrostatic pressure that would hold it up."""
    dn = n_w.dot(d)
    return p_i + rho_w * g.dot(n_w) * dn + grad_t.dot(d - dn * n_w)


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
