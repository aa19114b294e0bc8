"""Cubic B-spline kernel: Taichi functions against their numpy twins, normalisation, lattice sums."""

import math

import numpy as np
import pytest
import taichi as ti

from taichi_sph.sph import kernels
from taichi_sph.sph.kernels import SUPPORT_FACTOR, dw_dr_np, lattice_sums, sigma, w_np


@ti.kernel
def _eval_w(r: ti.types.ndarray(), h: float, dim: ti.template(), out_w: ti.types.ndarray(), out_dw: ti.types.ndarray()):
    for k in range(r.shape[0]):
        out_w[k] = kernels.w(r[k], h, dim)
        out_dw[k] = kernels.dw_dr(r[k], h, dim)


@ti.kernel
def _eval_grad(rij: ti.types.ndarray(), h: float, dim: ti.template(), out: ti.types.ndarray()):
    for k in range(rij.shape[0]):
        v = ti.Vector.zero(float, dim)
        for d in ti.static(range(dim)):
            v[d] = rij[k, d]
        g = kernels.grad_w(v, v.norm(), h, dim)
        for d in ti.static(range(dim)):
            out[k, d] = g[d]


def taichi_w(r, h, dim):
    r = np.ascontiguousarray(r, dtype=np.float64)
    out_w = np.zeros_like(r)
    out_dw = np.zeros_like(r)
    _eval_w(r, h, dim, out_w, out_dw)
    return out_w, out_dw


def taichi_grad(rij, h, dim):
    rij = np.ascontiguousarray(rij, dtype=np.float64)
    out = np.zeros_like(rij)
    _eval_grad(rij, h, dim, out)
    return out


def full_lattice(dim):
    """Offsets x_j - x_i of all unit-lattice points inside the support (self excluded), h = 1.2 dx."""
    n = int(math.ceil(SUPPORT_FACTOR)) + 1
    rng = np.arange(-n, n + 1, dtype=float)
    pts = np.stack([g.ravel() for g in np.meshgrid(*([rng] * dim), indexing="ij")], axis=1)
    r = np.linalg.norm(pts, axis=1)
    return pts[(r > 0) & (r < SUPPORT_FACTOR)]


@pytest.mark.parametrize("dim", [2, 3])
def test_taichi_matches_numpy(ti_cpu, dim):
    h = 0.7
    r = np.concatenate([np.linspace(0.0, 2.5 * h, 2001), [h, 2.0 * h, 1e-12]])
    tw, tdw = taichi_w(r, h, dim)
    # Same formula in f64, only the order of the multiplications differs: a few ulps.
    scale = sigma(dim, h)
    assert np.max(np.abs(tw - w_np(r, h, dim))) < 1e-13 * scale
    assert np.max(np.abs(tdw - dw_dr_np(r, h, dim))) < 1e-13 * scale / h


@pytest.mark.parametrize("dim", [2, 3])
def test_grad_w_is_radial_derivative_times_unit_vector(ti_cpu, dim):
    h = 0.5
    rij = np.random.default_rng(1).uniform(-1.1, 1.1, size=(500, dim))
    r = np.linalg.norm(rij, axis=1)
    expected = (dw_dr_np(r, h, dim) / r)[:, None] * rij
    # f64 round-off of a product of three factors.
    assert np.allclose(taichi_grad(rij, h, dim), expected, rtol=1e-12, atol=1e-14 * sigma(dim, h) / h)


@pytest.mark.parametrize("dim", [2, 3])
def test_normalisation_radial_gauss(ti_cpu, dim):
    # W is a polynomial in r on [0, h] and [h, 2h]; times 2 pi r (2D) or 4 pi r^2 (3D) the integrand
    # has degree <= 5, so 8-point Gauss-Legendre per piece is exact: only round-off remains.
    h = 0.9
    xg, wg = np.polynomial.legendre.leggauss(8)
    total = 0.0
    for a, b in ((0.0, h), (h, 2.0 * h)):
        rr = 0.5 * (b - a) * xg + 0.5 * (a + b)
        tw, _ = taichi_w(rr, h, dim)
        shell = 2.0 * np.pi * rr if dim == 2 else 4.0 * np.pi * rr**2
        total += np.sum(0.5 * (b - a) * wg * tw * shell)
    assert abs(total - 1.0) < 1e-13


@pytest.mark.parametrize("dim, m, tol", [(2, 200, 1e-9), (3, 40, 1e-7)])
def test_normalisation_cartesian(ti_cpu, dim, m, tol):
    # Midpoint rule over the whole plane/space on a grid of spacing 2h/m. W is C^2 with compact
    # support, so the rule converges fast: measured error 5e-12 (2D, m=200) and 3e-9 (3D, m=40).
    # The tolerances leave a margin of ~30-200x and are still 1e5 times smaller than the error of a
    # wrong normalisation constant (sigma_d values differ by tens of percent between forms).
    h = 1.0
    d = 2.0 * h / m
    g = (np.arange(-m, m) + 0.5) * d
    grids = np.meshgrid(*([g] * dim), indexing="ij")
    r = np.sqrt(sum(c**2 for c in grids)).ravel()
    tw, _ = taichi_w(r, h, dim)
    assert abs(tw.sum() * d**dim - 1.0) < tol


@pytest.mark.parametrize("dim, neighbours", [(2, 20), (3, 56)])
def test_partition_of_unity_on_lattice(ti_cpu, dim, neighbours):
    s = lattice_sums(dim)
    assert s["neighbours"] == neighbours
    # The lattice sum sum_j W_ij dx^d is a Riemann sum of the integral (= 1); it is exact only for
    # special h/dx ratios. With h = 1.2 dx the aliasing error is measured at 0.99976 (2D) and
    # 1.00081 (3D); 2e-3 bounds both while catching a wrong sigma_d or support radius.
    assert abs(s["kernel_sum"] - 1.0) < 2e-3
    # same sum from the Taichi function (self term W(0) included); identical terms, round-off only
    tw, _ = taichi_w(np.linalg.norm(full_lattice(dim), axis=1), SUPPORT_FACTOR / 2.0, dim)
    w0, _ = taichi_w(np.zeros(1), SUPPORT_FACTOR / 2.0, dim)
    assert abs(tw.sum() + w0[0] - s["kernel_sum"]) < 1e-13


@pytest.mark.parametrize("dim, raw_moment", [(2, 0.991), (3, 0.982)])
def test_gradient_on_full_lattice(ti_cpu, dim, raw_moment):
    h = SUPPORT_FACTOR / 2.0
    p = full_lattice(dim)  # x_j - x_i with dx = 1, V_j = 1
    grad = taichi_grad(-p, h, dim)  # grad_i W_ij with r_ij = x_i - x_j = -p
    # The lattice is point-symmetric: the terms cancel in pairs, leaving round-off of ~60 terms of
    # size <= 0.2.
    assert np.max(np.abs(grad.sum(axis=0))) < 1e-13
    m = p.T @ grad  # sum_j V_j (x_j - x_i) outer grad_i W_ij
    # The unnormalised cubic spline's lattice moment departs from the continuum's identity like the
    # kernel sum does (0.99079 in 2D, 0.98169 in 3D; 1e-3 fails for a wrong derivative, sign or
    # support); the gradient is divided by it, so the lattice moment is the identity to round-off
    # (~60 terms of size <= 0.2).
    assert abs(kernels._raw_gradient_moment(dim) - raw_moment) < 1e-3
    assert abs(kernels.GRADIENT_SCALE[dim] * kernels._raw_gradient_moment(dim) - 1.0) < 1e-15
    assert np.all(np.abs(np.diag(m) - 1.0) < 1e-13)
    assert abs(m[0, 0] - lattice_sums(dim)["gradient_moment"]) < 1e-13
    # off-diagonals cancel by the lattice's mirror symmetry: round-off only
    assert np.max(np.abs(m - np.diag(np.diag(m)))) < 1e-13
    # cubic lattice: all diagonal entries equal (round-off only)
    assert np.ptp(np.diag(m)) < 1e-13


@pytest.mark.parametrize("dim", [2, 3])
def test_derivative_matches_finite_difference(ti_cpu, dim):
    h = 0.8
    r = np.linspace(0.01 * h, 2.2 * h, 997)
    eps = 1e-5 * h
    wp, _ = taichi_w(r + eps, h, dim)
    wm, _ = taichi_w(r - eps, h, dim)
    _, dw = taichi_w(r, h, dim)
    # dw_dr is the derivative times the lattice normalisation GRADIENT_SCALE (kernels module doc)
    fd = (wp - wm) / (2.0 * eps) * kernels.GRADIENT_SCALE[dim]
    # Central difference: truncation eps^2/6 |W'''| (W''' is bounded, |W'''| <= 4.5 sigma/h^3), plus
    # round-off ~1e-16 sigma / eps; both are below 1e-9 sigma/h, 1e-8 leaves margin.
    assert np.max(np.abs(fd - dw)) < 1e-8 * sigma(dim, h) / h


@pytest.mark.parametrize("dim", [2, 3])
def test_compact_support_and_continuity(ti_cpu, dim):
    h = 0.6
    beyond = np.array([2.0 * h, 2.0 * h * (1 + 1e-15), 2.1 * h, 3.0 * h, 100.0 * h])
    tw, tdw = taichi_w(beyond, h, dim)
    # exactly zero at and beyond q = 2
    assert np.all(tw == 0.0) and np.all(tdw == 0.0)
    assert np.all(w_np(beyond, h, dim) == 0.0) and np.all(dw_dr_np(beyond, h, dim) == 0.0)
    # continuity across q = 1 and q = 2: values 2e-10 h apart differ by at most
    # max|W'| * 2e-10 h ~ 1e-10 sigma (W' and W'' are bounded by 1 sigma/h and 3 sigma/h^2).
    d = 1e-10 * h
    for q in (1.0, 2.0):
        tw, tdw = taichi_w(np.array([q * h - d, q * h + d]), h, dim)
        s = sigma(dim, h)
        assert abs(tw[0] - tw[1]) < 1e-9 * s
        assert abs(tdw[0] - tdw[1]) < 1e-9 * s / h
    # the two branches agree exactly at q = 1: 1 - 1.5 + 0.75 = 0.25 (2 - 1)^3 and -3 + 2.25 = -0.75 (2 - 1)^2
    tw, tdw = taichi_w(np.array([h]), h, dim)
    assert tw[0] == pytest.approx(0.25 * sigma(dim, h), rel=1e-14)
    assert tdw[0] == pytest.approx(-0.75 * sigma(dim, h) / h * kernels.GRADIENT_SCALE[dim], rel=1e-14)
