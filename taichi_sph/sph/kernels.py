"""Cubic B-spline smoothing kernel, shared by both solver modes.

Seed 000 uses the cubic B-spline with support radius r_e = 2.4 dx (its "h = 2.4 dx" is the support
radius); the smoothing length is h = r_e / 2, so the kernel vanishes for r >= 2 h. Seed 002 eq (8) is
the same function. Normalisation sigma_d: 2/(3h) in 1D, 10/(7 pi h^2) in 2D, 1/(pi h^3) in 3D.

    W(q) = sigma_d * (1 - 1.5 q^2 + 0.75 q^3)   0 <= q < 1
         = sigma_d * 0.25 (2 - q)^3             1 <= q < 2
         = 0                                    q >= 2,       q = r / h

Gradient normalised to the particle lattice. On the square/cubic lattice of spacing dx the first
moment of the kernel gradient, sum_j V_j (x_j - x_i) (x) grad_i W_ij with V_j = dx^d, is G I with
G = 0.99079 (2D) / 0.98169 (3D) instead of I (the continuous integral): the SPH gradient of a linear
field (eq 12-13, 34-36), the divergence (eq 23) and the Laplacian of a quadratic field (eq 14, 22, 24)
all read G times the exact value. As r_e / dx is fixed, that error does not shrink with dx. dW/dr is
therefore divided by G (`GRADIENT_SCALE`), which makes these operators exact on the lattice. A
constant factor keeps every symmetric pair form antisymmetric (momentum is conserved as before), and
the kernel-gradient-corrected gradient (L_i grad W) does not change.
"""

import math

import numpy as np
import taichi as ti

from .support import SUPPORT_FACTOR


def sigma(dim: int, h: float) -> float:
    """Normalisation constant of the cubic B-spline in `dim` dimensions."""
    if dim == 1:
        return 2.0 / (3.0 * h)
    if dim == 2:
        return 10.0 / (7.0 * math.pi * h * h)
    if dim == 3:
        return 1.0 / (math.pi * h**3)
    raise ValueError(f"dim must be 1, 2 or 3, not {dim}")


@ti.func
def _sigma(h, dim: ti.template()):
    """Normalisation sigma_d (same as `sigma`, inside kernels)."""
    s = 0.0
    if ti.static(dim == 1):
        s = 2.0 / (3.0 * h)
    elif ti.static(dim == 2):
        s = 10.0 / (7.0 * math.pi * h * h)
    else:
        s = 1.0 / (math.pi * h * h * h)
    return s


@ti.func
def w(r, h, dim: ti.template()):
    """Kernel value W(r, h)."""
    q = r / h
    s = _sigma(h, dim)
    val = 0.0
    if q < 1.0:
        val = s * (1.0 - 1.5 * q * q + 0.75 * q * q * q)
    elif q < 2.0:
        val = s * 0.25 * (2.0 - q) ** 3
    return val


def _dw_dq_shape_np(q: np.ndarray) -> np.ndarray:
    """d/dq of the unnormalised cubic B-spline shape, numpy."""
    return np.where(q < 1.0, -3.0 * q + 2.25 * q**2, np.where(q < 2.0, -0.75 * (2.0 - q) ** 2, 0.0))


def _lattice_points(dim: int, support_factor: float) -> np.ndarray:
    """Lattice offsets (unit spacing) strictly inside the support, the origin excluded."""
    n = int(math.ceil(support_factor)) + 1
    rng = np.arange(-n, n + 1, dtype=float)
    pts = np.stack([g.ravel() for g in np.meshgrid(*([rng] * dim), indexing="ij")], axis=1)
    r = np.linalg.norm(pts, axis=1)
    return pts[(r > 0) & (r < support_factor)]


def _raw_gradient_moment(dim: int, support_factor: float = SUPPORT_FACTOR) -> float:
    """G = sum_j (x_j - x_i)_0 dW_ij/dx_i0 dx^d of the unnormalised gradient on the lattice."""
    h = support_factor / 2.0
    p = _lattice_points(dim, support_factor)
    r = np.linalg.norm(p, axis=1)
    dwdr = sigma(dim, h) / h * _dw_dq_shape_np(r / h)
    # x_i = 0, rij = -p; grad_i W = dW/dr * rij / r; moment = sum (x_j - x_i)_0 * grad_i W_0
    return float(np.sum(p[:, 0] * dwdr * (-p[:, 0]) / r))


#: factor on dW/dr per dimension: 1 / G, G the lattice moment of the unnormalised gradient (module doc)
GRADIENT_SCALE = {d: 1.0 / _raw_gradient_moment(d) for d in (1, 2, 3)}


@ti.func
def dw_dr(r, h, dim: ti.template()):
    """Radial derivative dW/dr (<= 0), lattice-normalised (module doc)."""
    q = r / h
    s = _sigma(h, dim) * ti.static(GRADIENT_SCALE[dim])
    val = 0.0
    if q < 1.0:
        val = s / h * (-3.0 * q + 2.25 * q * q)
    elif q < 2.0:
        val = -s / h * 0.75 * (2.0 - q) ** 2
    return val


@ti.func
def w_and_dw_dr(r, h, dim: ti.template()):
    """Kernel value W and radial derivative dW/dr (lattice-normalised as `dw_dr`) together, for
    0 <= r < 2 h (one branch on q)."""
    q = r / h
    s = _sigma(h, dim)
    sg = s * ti.static(GRADIENT_SCALE[dim])
    val = 0.0
    der = 0.0
    if q < 1.0:
        val = s * (1.0 - 1.5 * q * q + 0.75 * q * q * q)
        der = sg / h * (-3.0 * q + 2.25 * q * q)
    else:
        t = 2.0 - q
        val = s * 0.25 * t * t * t
        der = -sg / h * 0.75 * t * t
    return val, der


@ti.func
def grad_w(rij, r, h, dim: ti.template()):
    """Gradient of W with respect to x_i, with rij = x_i - x_j and r = |rij| > 0."""
    return dw_dr(r, h, dim) * rij / r


# ---- numpy twins, used by scene building and tests (no Taichi runtime needed) ----

def w_np(r: np.ndarray, h: float, dim: int) -> np.ndarray:
    """Kernel value on numpy arrays; same formula as `w`."""
    q = np.asarray(r, dtype=float) / h
    out = np.where(q < 1.0, 1.0 - 1.5 * q**2 + 0.75 * q**3, np.where(q < 2.0, 0.25 * (2.0 - q) ** 3, 0.0))
    return sigma(dim, h) * out


def dw_dr_np(r: np.ndarray, h: float, dim: int) -> np.ndarray:
    """Radial derivative on numpy arrays; same formula as `dw_dr` (lattice-normalised)."""
    q = np.asarray(r, dtype=float) / h
    return sigma(dim, h) * GRADIENT_SCALE[dim] / h * _dw_dq_shape_np(q)


def lattice_sums(dim: int, support_factor: float = SUPPORT_FACTOR) -> dict:
    """Sums over a full square/cubic lattice of unit spacing around one particle.

    Returns the neighbour count (self excluded), the kernel sum S = sum_j W_ij dx^d (self
    included; the lattice's departure from partition of unity), and the gradient-moment factor
    G = sum_j (x_j - x_i)_0 dW_ij/dx_i0 dx^d (1 for an exact first-order gradient; 1 by construction of
    `GRADIENT_SCALE` at the default support). These constants make reference densities and
    free-surface thresholds consistent with the discrete lattice.
    """
    h = support_factor / 2.0
    p = _lattice_points(dim, support_factor)
    r = np.linalg.norm(p, axis=1)
    s = float(w_np(np.zeros(1), h, dim)[0] + w_np(r, h, dim).sum())
    g = _raw_gradient_moment(dim, support_factor) * GRADIENT_SCALE[dim]
    return {"neighbours": len(p), "kernel_sum": s, "gradient_moment": g}


def lattice_kernel_sum(dim: int, spacing: float, support_factor: float = SUPPORT_FACTOR) -> tuple[float, int]:
    """Kernel sum S = sum_j W_ij s^d (self included) and neighbour count (self excluded) over a
    square/cubic lattice of spacing s (in units of the particle spacing dx; h = support_factor / 2 as
    everywhere). s = 1 gives lattice_sums' values; s > 1 is water spread through ground of porosity
    eps = s^-d."""
    h = support_factor / 2.0
    r = np.linalg.norm(_lattice_points(dim, support_factor / spacing), axis=1) * spacing
    return float((w_np(np.zeros(1), h, dim)[0] + w_np(r, h, dim).sum()) * spacing**dim), len(r)
