"""Porosity of water particles from fixed soil markers (seed 000 section 4, eq 32) and the
coefficients of the unified momentum equation (eq 9a-d).

eq 32:  eps_i = max(min(1, 2 - 2 S_i), eps0_i),  S_i = sum_{j in soil} W_ij V_j,
with V_j the marker volume. Beyond the seed, every marker carries its own eps0 and D50; at a water
particle they are the kernel-weighted means sum_j W_ij V_j q_j / S_i of the markers around it, so
layered ground (armour over core) works. Markers never move: they are binned and sorted into cells
once, at construction; each step only the sums over the markers near each particle are taken.
"""

from typing import NamedTuple

import numpy as np
import taichi as ti

from ..sph import kernels
from ..sph.grid import NeighbourGrid


@ti.func
def inertia_coefficient(eps):
    """Cr(eps) = 1 + 0.34 (1 - eps) / eps (eq 9a): added mass of the grains."""
    return 1.0 + 0.34 * (1.0 - eps) / eps


@ti.func
def linear_drag(eps, nu, d50, alpha_c):
    """a(eps) = alpha_c nu_w (1 - eps)^2 / (eps^3 D50^2) (eq 9c), 1/s."""
    return alpha_c * nu * (1.0 - eps) ** 2 / (eps**3 * d50 * d50)


@ti.func
def quadratic_drag(eps, d50, beta_c):
    """b(eps) = beta_c (1 - eps) / (eps^3 D50) (eq 9d), 1/m."""
    return beta_c * (1.0 - eps) / (eps**3 * d50)


def linear_drag_np(eps, nu, d50, alpha_c):
    return alpha_c * nu * (1.0 - eps) ** 2 / (eps**3 * d50**2)


def quadratic_drag_np(eps, d50, beta_c):
    return beta_c * (1.0 - eps) / (eps**3 * d50)


def terminal_darcy_velocity(eps, nu, d50, alpha_c=1000.0, beta_c=1.1, g=9.81, gradient=1.0):
    """Steady Darcy velocity of water driven by gravity through uniform ground: the positive root
    of a vD + b vD^2 = (g / eps) * gradient (eq 8 with d/dt = 0, uniform flow, no pressure gradient
    for gradient = 1)."""
    a = linear_drag_np(eps, nu, d50, alpha_c)
    b = quadratic_drag_np(eps, d50, beta_c)
    rhs = g / eps * gradient
    if b == 0.0:
        return rhs / a
    return (-a + np.sqrt(a * a + 4.0 * b * rhs)) / (2.0 * b)


def falling_head_level(h0, length, eps, d50, t_end, nu=1.0e-6, g=9.81, alpha_c=1000.0, beta_c=1.1,
                       inertia=False):
    """Falling-head permeameter reference (SPEC 5): water of height h above a plug of length L drains
    through it. Quasi-steady (default): a vD + b vD^2 = (g / eps) (h + L) / L and dh/dt = -vD, the Darcy
    velocity at every instant the steady one of the present head (inertia neglected). With
    `inertia=True`, the momentum balance of the column and the plug together, started from rest:
    (h + Cr L) dvD/dt = g (h + L) - eps L (a vD + b vD^2), dh/dt = -vD, Cr = 1 + 0.34 (1 - eps) / eps
    (eq 9a): the column (free water, velocity vD) and the plug's pore water (eq 8: Cr dvD/dt = g - grad
    P / rho_w - eps (a + b |vD|) vD) accelerated by the head between the column's surface and the plug's
    exit face, both at atmospheric pressure. Its steady state is the quasi-steady ODE; from rest it lags
    it by the distance the water needs to reach the Darcy velocity (2.5 % of h0 after 50 ms for
    configs/permeameter.yaml). Returns h(t) as a callable (dense ODE solution on [0, t_end])."""
    from scipy.integrate import solve_ivp

    if not inertia:
        def rhs(_t, y):
            return [-terminal_darcy_velocity(eps, nu, d50, alpha_c, beta_c, g, (max(y[0], 0.0) + length) / length)]

        sol = solve_ivp(rhs, (0.0, t_end), [h0], dense_output=True, rtol=1e-9, atol=1e-12).sol
        return lambda t: sol(t)[0]
    a = linear_drag_np(eps, nu, d50, alpha_c)
    b = quadratic_drag_np(eps, d50, beta_c)
    cr = 1.0 + 0.34 * (1.0 - eps) / eps

    def rhs_inertial(_t, y):
        h, v = max(y[0], 0.0), y[1]
        return [-v, (g * (h + length) - eps * length * (a * v + b * v * abs(v))) / (h + cr * length)]

    sol = solve_ivp(rhs_inertial, (0.0, t_end), [h0, 0.0], dense_output=True, rtol=1e-10, atol=1e-12).sol
    return lambda t: sol(t)[0]


class FallingHead(NamedTuple):
    """A permeameter's level against the falling-head references (falling_head_deviation)."""

    ref: np.ndarray  # the ODE with inertia at the frames' times (m)
    ref_quasi: np.ndarray  # the quasi-steady ODE (m)
    deviation: np.ndarray  # h / ref - 1
    deviation_quasi: np.ndarray  # h / ref_quasi - 1
    first_half: np.ndarray  # frames where the quasi-steady level is still above h0 / 2


def falling_head_deviation(times, h, length, eps, d50) -> FallingHead:
    """A falling-head permeameter's level h at `times` (h[0] at t = 0; column_level) against the ODE with
    inertia and the quasi-steady one (falling_head_level, both from h[0]), and the first half of the
    drain, the frames over which docs/validation.md takes the largest deviation."""
    t = np.asarray(times, dtype=float)
    h = np.asarray(h, dtype=float)
    ode = falling_head_level(h[0], length, eps, d50, t_end=t[-1], inertia=True)
    quasi = falling_head_level(h[0], length, eps, d50, t_end=t[-1])
    ref = np.array([ode(tk) for tk in t])
    ref_q = np.array([quasi(tk) for tk in t])
    return FallingHead(ref, ref_q, h / ref - 1.0, h / ref_q - 1.0, ref_q >= 0.5 * h[0])


def penetration_front(h0, depth, eps, d50, t_end=5.0, nu=1.0e-6, g=9.81, alpha_c=1000.0, beta_c=1.1):
    """One-dimensional reference for water of height h0 released on dry ground of porosity eps and
    thickness `depth` (the seed's free fall, seed 000 section 5, without its tank's walls): a sharp front
    at depth z below the ground's surface, the ground saturated behind it, atmospheric pressure at the
    water's top and at the front (no capillarity). The column above the ground (height h, velocity vD) and
    the pore water behind the front (eq 8 with the Darcy velocity vD, which is continuous across the
    ground's surface) move together:

        (h + Cr z) dvD/dt = g (h + z) - eps z (a vD + b vD^2),   dh/dt = -vD,   dz/dt = vD / eps,

    from rest with z = 0 (free fall until the front has entered), a, b, Cr of eq 9a-d: the falling-head
    balance (falling_head_level) with a plug that grows as the front advances. Returns (z, arrival): z(t)
    as a callable on [0, arrival] (the front's depth), and the time the front reaches `depth`; at that
    moment eps depth / h0 of the water is in the ground. Arrival is inf where the column has gone into the
    ground first (h0 < eps depth) or not by t_end."""
    from scipy.integrate import solve_ivp

    a = linear_drag_np(eps, nu, d50, alpha_c)
    b = quadratic_drag_np(eps, d50, beta_c)
    cr = 1.0 + 0.34 * (1.0 - eps) / eps

    def rhs(_t, y):
        h, z, v = y
        return [-v, v / eps, (g * (h + z) - eps * z * (a * v + b * v * abs(v))) / (h + cr * z)]

    def reached(_t, y):
        return y[1] - depth

    def emptied(_t, y):  # the column has gone into the ground: a slug, which this balance does not hold
        return y[0]

    reached.terminal = emptied.terminal = True
    sol = solve_ivp(rhs, (0.0, t_end), [h0, 0.0, 0.0], events=(reached, emptied), dense_output=True,
                    rtol=1e-10, atol=1e-12)
    arrival = float(sol.t_events[0][0]) if len(sol.t_events[0]) else float("inf")
    if not len(sol.t_events[0]) and len(sol.t_events[1]) and sol.y_events[1][0][1] >= depth * (1.0 - 1e-9):
        # the column empties as the front arrives (h0 = eps depth: the events coincide, and which of the
        # two the solver finds first is rounding): the front has reached the bottom
        arrival = float(sol.t_events[1][0])
    return (lambda t: float(sol.sol(t)[1])), arrival



def share_against_front(times, share, h0, depth, eps, d50):
    """A run against penetration_front: the signed largest of share(k) - eps z(t_k) / h0 over the times
    t_k = times[k] up to the front's arrival, where share(k) is the run's share of the water that has
    entered the ground at t_k (called only for those times) and eps z / h0 the front's. Returns (that
    deviation, the front's arrival, how many times were compared)."""
    z, arrival = penetration_front(h0, depth, eps, d50)
    dev = [share(k) - eps * z(t) / h0 for k, t in enumerate(times) if t <= arrival]
    return (dev[int(np.argmax(np.abs(dev)))] if dev else float("nan")), arrival, len(dev)


def bulk_front_arrival(times, share, eps, depth, h0):
    """The time a run's water body reaches the bottom of ground of porosity eps and thickness `depth`, as
    penetration_front defines it: when the share of the water that has entered the ground, share[k] at
    times[k], first reaches eps depth / h0 (the ground behind the front saturated; seed 000 section 5
    reads its arrival where about eps of the water fills the layer), interpolated linearly between the
    two times about it. Counted without a kernel, it does not hang on the one particle that leads the
    front by a spacing, as the lowest particle's arrival does; it moves as rows of particles cross the
    ground's surface, which at a coarse spacing is in steps (dx 2 cm: a row is 0.1 of the free fall's
    water). nan if not reached after the first time."""
    share = np.asarray(share, dtype=float)
    level = eps * depth / h0
    # a share that reaches the level exactly (whole rows of particles: 0.3 of 1000 water particles)
    # counts, whatever the rounding of depth / h0 from the run's geometry
    k = np.flatnonzero(share >= level - 1e-9)
    if not len(k) or k[0] == 0:
        return float("nan")
    k = int(k[0])
    part = min(1.0, (level - share[k - 1]) / (share[k] - share[k - 1]))
    return float(times[k - 1] + part * (times[k] - times[k - 1]))


def slab_count(z, lo, hi, thickness):
    """How many particles at heights z lie between lo and hi, each counted as a slab of its own
    `thickness` centred on it: the share of each slab inside [lo, hi], summed. A count of the centres
    moves by a whole row as a row crosses lo or hi (a coarse layer's core holds a few rows of the pore
    water); counted as slabs of the row spacing, a lattice of rows gives the same count whatever its
    offset, (hi - lo) / thickness rows. No kernel: the water the slabs hold, not what a kernel reads."""
    z = np.asarray(z, dtype=float)
    inside = np.minimum(z + 0.5 * thickness, hi) - np.maximum(z - 0.5 * thickness, lo)
    return float(np.sum(np.clip(inside, 0.0, thickness)) / thickness)


def column_level(z, base, dx):
    """Height above `base` of the free surface of a water column whose particles sit at heights z: the
    mean height of its top row (within dx / 2 of the highest particle) plus dx / 2, the top of those
    particles; 0 when no particle is above base. The measure the falling-head reference compares with
    (a count of the particles above base moves in steps of a row as the column crosses base)."""
    z = np.asarray(z, dtype=float)
    z = z[z > base]
    if z.size == 0:
        return 0.0
    top = z[z > z.max() - 0.5 * dx]
    return max(float(top.mean()) + 0.5 * dx - base, 0.0)


def lattice_table(dim: int, n: int = 96, eps_min: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For water in ground of porosity eps (pore lattice of spacing dx eps^(-1/dim)), tabulated on n
    porosities in [eps_min, 1]: the lattice kernel sum K(eps) and the lattice neighbour count
    N(eps). Number densities are divided by K(eps_i), so water at rest on its pore lattice has
    <rho> = eps rho_w exactly; the free-surface count threshold is N_surf N(eps) / N(1)."""
    eps = np.linspace(eps_min, 1.0, n)
    vals = [kernels.lattice_kernel_sum(dim, e ** (-1.0 / dim)) for e in eps]
    return eps, np.array([v[0] for v in vals]), np.array([float(v[1]) for v in vals])


@ti.data_oriented
class MarkerSet:
    """Fixed soil markers in cell order, and the porosity kernel that reads them. With `serial` (the
    solver's small-scene flag, on the CPU only) the kernel's loop runs on the calling thread."""

    def __init__(self, markers: dict, dim: int, lo, hi, support_radius: float, serial: bool = False):
        self.dim = dim
        self.serial = bool(serial)
        self.m = m = len(markers["position"])
        self.re = support_radius
        self.h = 0.5 * support_radius
        self.position = ti.Vector.field(dim, float, m)
        self.eps0 = ti.field(float, m)
        self.d50 = ti.field(float, m)
        self.volume = ti.field(float, m)
        fp = np.float64 if self.position.dtype == ti.f64 else np.float32  # the run's precision
        self.position.from_numpy(np.asarray(markers["position"], dtype=fp))
        self.eps0.from_numpy(np.asarray(markers["eps0"], dtype=fp))
        self.d50.from_numpy(np.asarray(markers["d50"], dtype=fp))
        self.volume.from_numpy(np.asarray(markers["volume"], dtype=fp))
        # markers outside the particle grid box grown by one support radius cannot be reached by any
        # particle: the grid drops them (the margin keeps the images of markers across a periodic side)
        lo = np.asarray(lo, float) - support_radius
        hi = np.asarray(hi, float) + support_radius
        self.grid = NeighbourGrid(m, dim, lo, hi, support_radius, 1)
        active = ti.field(ti.i32, m)
        active.fill(1)
        self.grid.sort(self.position, active, m)
        for f in (self.position, self.eps0, self.d50, self.volume):
            self.grid.reorder(f, m)
        self.ncell = self.grid.ncell
        self._lo = [float(v) for v in lo]
        self.cell_size = float(support_radius)

    @ti.kernel
    def porosity(self, x: ti.template(), mask: ti.template(), n: ti.i32, eps: ti.template(),
                 d50: ti.template(), reach: ti.template()):
        """eps_i (eq 32) and the local D50 for the first n particles with mask 1; eps = 1 elsewhere.
        reach_i is 1 where a marker of porosity below 1 lies within the support (the outer half of a face's
        ramp, where eq 32 still gives eps 1, included), else 0."""
        ti.loop_config(serialize=self.serial)
        for i in range(n):
            e = 1.0
            dloc = 1.0
            near = 0
            if mask[i] == 1:
                xi = x[i]
                cc = ti.Vector.zero(ti.i32, ti.static(self.dim))
                inside = 1
                for d in ti.static(range(self.dim)):
                    c = ti.cast(ti.floor((xi[d] - ti.static(self._lo[d])) / ti.static(self.cell_size)), ti.i32)
                    if c < -1 or c > ti.static(self.ncell[d]):
                        inside = 0
                    cc[d] = c
                s = 0.0
                se = 0.0
                sd = 0.0
                if inside == 1:
                    for off in ti.static(ti.grouped(ti.ndrange(*([(-1, 2)] * self.dim)))):
                        ok = 1
                        lin = 0
                        for d in ti.static(range(self.dim)):
                            nd = cc[d] + off[d]
                            if nd < 0 or nd >= ti.static(self.ncell[d]):
                                ok = 0
                            lin = lin * ti.static(self.ncell[d]) + nd
                        if ok == 1:
                            for j in range(self.grid.cell_start[lin], self.grid.cell_start[lin + 1]):
                                r = (xi - self.position[j]).norm()
                                if r < ti.static(self.re):
                                    wv = kernels.w(r, ti.static(self.h), ti.static(self.dim)) * self.volume[j]
                                    s += wv
                                    se += wv * self.eps0[j]
                                    sd += wv * self.d50[j]
                if s > 0.0:
                    e = ti.max(ti.min(1.0, 2.0 - 2.0 * s), se / s)
                    dloc = sd / s
                    if se < s:  # ground of porosity below 1 (eps0 = 1 markers are free water)
                        near = 1
            eps[i] = e
            d50[i] = dloc
            reach[i] = near
