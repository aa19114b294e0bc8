"""Walls of both modes: what a fluid or soil particle sees at a wall particle, and the wall particles' own
pressure.

Wall particles are fixed boundary particles (or an obstacle's, moved by sph/wall_motion.py). A particle i
does not read a wall particle's stored state in its sums: it sees the wall's image of its own state,
mirrored across the wall's face (the virtual-marker idea of seed 000, Asai et al. 2013; Morris et al.
1997 and Takeda et al. 1994 for eq 50-51 of seed 002):

- velocity: `mirror_velocity` (mode isph: slip reverses the normal component relative to the wall,
  no-slip the whole velocity) and `boundary_beta` with `boundary_relative_velocity` (mode wcsph_biot,
  eq 50-51: the virtual velocity extrapolated behind the face);
- pressure: `wall_pressure` (hydrostatic Neumann condition P_w = P_i + rho g . (x_w - x_i)) and
  `wall_pressure_along_face` (hydrostatic across the face, the fluid's own gradient along it);
  `wall_mirror_solve` closes a gradient sum whose wall terms carry the particle's own gradient along
  the face (used for pressure in mode wcsph_biot and for the soil's stress and pore pressure).

`WallPressure` gives each wall particle one pressure for output (and, in mode isph, for the corrector's
wall terms): the Shepard mean over the fluid particles that see it of the value each one sees
(Adami et al. 2012). A solver supplies which particles see walls and the (weight, value) a pair gives.
"""

import taichi as ti

from ..kinds import WALL


@ti.func
def mirror_velocity(v_i, v_w, n_w, no_slip: ti.template()):
    """Velocity a wall particle (moving at v_w, zero for fixed walls) takes as seen from fluid particle i
    (virtual-marker idea of seed 000, evaluated at i itself): relative to the wall, no-slip reverses the
    whole velocity, slip only its normal component."""
    u = v_i - v_w
    out = -u
    if ti.static(not no_slip):
        out = u - 2.0 * u.dot(n_w) * n_w
    return v_w + out


@ti.func
def boundary_beta(d_b, d_a, beta_max):
    """beta = min(beta_max, 1 + d_B / d_a) of eq 51 (seed 002): d_B the boundary particle's distance behind
    the wall surface, d_a the fluid particle's distance in front of it (beta_max when d_a <= 0)."""
    beta = beta_max
    if d_a > 0.0:
        beta = ti.min(beta_max, 1.0 + d_b / d_a)
    return beta


@ti.func
def boundary_relative_velocity(v_a, n_w, beta, no_slip: ti.template()):
    """v_a - v_B of eq 50 (seed 002), v_a the fluid velocity relative to the wall (v_a - v_w for a moving
    wall, sph/wall_motion.py): beta v_a (no-slip, Morris/Takeda), or beta (v_a . n) n for a slip wall (no
    tangential shear; the normal component as for no-slip)."""
    out = beta * v_a
    if ti.static(not no_slip):
        out = beta * v_a.dot(n_w) * n_w
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


#: below this |det(I - m_wall)| the mirror solves do not invert (a particle with walls over most of its
#: support, in a corner): the walls then carry no extrapolation along their faces
MIRROR_DET_MIN = 0.25


@ti.func
def wall_mirror_solve(s, m_wall, along_equilibrium):
    """Gradient-like sum G = s + m_wall G of a particle whose wall neighbours carry the mirror image of
    the field along their faces (docs/wcsph.md, "Walls"): G = (I - m_wall)^-1 s, m_wall = sum over walls
    V grad W (x) d_t. Where I - m_wall is near singular (det < 0.25), the walls take the equilibrium
    gradient along their faces too: s + along_equilibrium, the same terms with that gradient."""
    a = ti.Matrix.identity(float, s.n) - m_wall
    out = s + along_equilibrium
    if ti.abs(a.determinant()) > MIRROR_DET_MIN:
        out = a.inverse() @ s
    return out


@ti.func
def wall_mirror_solve_rows(s, m_wall):
    """`wall_mirror_solve` for each row of a matrix of gradient-like sums (row a the gradient of field
    component a, such as the velocity gradient L_ab = d v_a / d x_b), whose wall neighbours carry the
    field extrapolated along their faces with that gradient: L = s + L M, M = m_wall^T, so L = s (I -
    m_wall^T)^-1, the transpose of `wall_mirror_solve` on s^T. Where I - m_wall is near singular
    (det < 0.25) the walls add nothing along their faces: s."""
    return wall_mirror_solve(s.transpose(), m_wall, ti.Matrix.zero(float, s.m, s.n)).transpose()


@ti.data_oriented
class WallPressure:
    """Pressure of the wall particles of solver `fl`, P_w = sum_f W_wf P_w(f) / sum_f W_wf over the fluid
    particles f that see wall particle w (Adami et al. 2012), P_w(f) the value f sees there; 0 where no
    fluid particle sees the wall. `fl` holds the particle store (n, kind, p, grid, serial) and two ti.funcs:
    `_wall_source(i)`, whether particle i takes part, and `_wall_pressure_seen(i, j)`, the pair's kernel
    weight and the pressure i sees at wall particle j (weight 0 leaves the pair out)."""

    def __init__(self, fl, n):
        self.fl = fl
        self.num = ti.field(float, n)
        self.den = ti.field(float, n)

    @ti.kernel
    def update(self):
        """Writes fl.p of every wall particle."""
        fl = self.fl
        ti.loop_config(serialize=fl.serial)
        for i in range(fl.n):
            if fl.kind[i] == WALL:
                self.num[i] = 0.0
                self.den[i] = 0.0
        ti.loop_config(serialize=fl.serial)
        for i in range(fl.n):
            if fl._wall_source(i):
                for k in range(fl.grid.nbr_count[i]):
                    j = fl.grid.nbr[i, k]
                    if fl.kind[j] == WALL:
                        wij, pw = fl._wall_pressure_seen(i, j)
                        if wij > 0.0:
                            ti.atomic_add(self.num[j], wij * pw)
                            ti.atomic_add(self.den[j], wij)
        ti.loop_config(serialize=fl.serial)
        for i in range(fl.n):
            if fl.kind[i] == WALL:
                pw = 0.0
                if self.den[i] > 0.0:
                    pw = self.num[i] / self.den[i]
                fl.p[i] = pw
