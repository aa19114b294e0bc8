"""Periodic boundaries: the neighbour grid with wrapped cells against a brute-force minimum-image
search, the pair displacement and position wrap of sph/operators.py, and scenes without side walls."""

import numpy as np
import pytest
import taichi as ti

from taichi_sph.sph import operators
from taichi_sph.sph.grid import NeighbourGrid

RADIUS = 0.1


def min_image_neighbours(pos, period, radius, rows):
    """Brute force: all j != i with |x_i - x_j|^2 < r^2, the displacement wrapped to the nearest image
    along each axis of nonzero period."""
    L = np.asarray(period, float)
    per = L > 0
    out = {}
    for i in np.nonzero(rows)[0]:
        d = pos[i] - pos
        d[:, per] -= L[per] * np.floor(d[:, per] / L[per] + 0.5)
        js = np.nonzero((np.sum(d * d, axis=1) < radius * radius) & (np.arange(len(pos)) != i))[0]
        out[int(i)] = set(js.tolist())
    return out


@pytest.mark.parametrize("dim, period", [
    (2, (0.33, 0.0)),            # x periodic and bounded y; 3 cells along x, the fewest allowed
    (2, (0.71, 0.47)),           # doubly periodic, the last axis too (its cells taken one by one)
    (3, (0.52, 0.0, 0.44)),      # a periodic first and last axis around a bounded middle one
])
def test_periodic_lists_match_min_image_brute_force(ti_cpu, dim, period):
    n = 1500 if dim == 2 else 2500
    rng = np.random.default_rng(7)
    lo = np.full(dim, -0.1)
    hi = np.array([0.6, 0.6, 0.6][:dim])
    L = np.asarray(period)
    # along periodic axes the points start anywhere in [-L, 2L): sort() must wrap them, not drop them
    pos = rng.uniform(lo, hi, size=(n, dim))
    for d in range(dim):
        if L[d] > 0:
            pos[:, d] = rng.uniform(-L[d], 2 * L[d], size=n)
    pos[0, :] = np.where(L > 0, -1e-18, 0.0)  # wraps to just below L, or rounds to L: must land in [0, L)
    x = ti.Vector.field(dim, float, n)
    act = ti.field(ti.i32, n)
    msk = ti.field(ti.i32, n)
    x.from_numpy(pos)
    act.fill(1)
    msk.fill(1)
    grid = NeighbourGrid(n, dim, lo, hi, RADIUS, max_neighbours=400, period=period)
    for d in range(dim):
        if L[d] > 0:
            assert grid.ncell[d] == int(L[d] // RADIUS) >= 3
    left = grid.sort(x, act, n)
    assert len(left) == 0  # nothing leaves through a periodic side
    grid.reorder(x, n)
    grid.reorder(msk, n)
    xs = x.to_numpy()
    for d in range(dim):
        if L[d] > 0:
            assert xs[:, d].min() >= 0.0 and xs[:, d].max() < L[d]
    # the wrapped positions are the originals shifted by whole periods
    perm = grid.perm.to_numpy()[:n]
    shift = (xs - pos[perm]) / np.where(L > 0, L, 1.0)
    np.testing.assert_allclose(shift, np.round(shift), atol=1e-9)
    grid.build_neighbour_lists(x, msk, n, RADIUS)
    cnt = grid.nbr_count.to_numpy()[:n]
    nbr = grid.nbr.to_numpy()
    expect = min_image_neighbours(xs, period, RADIUS, np.ones(n, bool))
    wrapped_pairs = 0
    for i in range(n):
        got = nbr[i, : cnt[i]]
        assert len(got) == len(set(got.tolist())), f"row {i} lists a neighbour twice"
        assert set(got.tolist()) == expect[i], f"row {i}"
        wrapped_pairs += int(np.any(np.abs(xs[got] - xs[i]) > RADIUS))
    assert wrapped_pairs > 0.05 * n  # pairs across the periodic sides were really tested


def test_period_needs_three_cells(ti_cpu):
    with pytest.raises(ValueError, match="at least 3 cells"):
        NeighbourGrid(10, 2, [0, 0], [1, 1], RADIUS, 10, period=(0.29, 0.0))


@ti.kernel
def _rel_wrap(a: ti.template(), b: ti.template(), d: ti.template(), w: ti.template(), period: ti.template()):
    for i in range(a.shape[0]):
        d[i] = operators.rel(a[i], b[i], period)
        w[i] = operators.wrap(a[i], period)


def test_rel_and_wrap(ti_cpu):
    period = (1.0, 0.0)
    a_np = np.array([[0.05, 0.1], [0.95, 0.2], [-0.3, 0.5], [2.25, -3.0]])
    b_np = np.array([[0.95, 0.9], [0.05, 0.1], [0.4, 0.5], [0.0, 0.0]])
    fields = [ti.Vector.field(2, float, 4) for _ in range(4)]
    fields[0].from_numpy(a_np)
    fields[1].from_numpy(b_np)
    _rel_wrap(*fields, period)
    d, w = fields[2].to_numpy(), fields[3].to_numpy()
    # x: the nearest image (|d| <= L / 2); y: the plain difference
    np.testing.assert_allclose(d, [[0.1, -0.8], [-0.1, 0.1], [0.3, 0.0], [0.25, -3.0]], atol=1e-12)
    np.testing.assert_allclose(w, [[0.05, 0.1], [0.95, 0.2], [0.7, 0.5], [0.25, -3.0]], atol=1e-12)
