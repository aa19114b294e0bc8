"""Neighbour grid: counting sort, reorder and neighbour lists against a brute-force search."""

import numpy as np
import pytest
import taichi as ti
from scipy.spatial import cKDTree

from taichi_sph.sph.grid import NeighbourGrid, NeighbourOverflowError

CELL = 0.1
RADIUS = 0.1  # = cell size, the largest radius the grid allows


def make_case(dim, n, capacity, seed):
    """Random particles in a box that does not fit a whole number of cells, some outside it, some inactive."""
    rng = np.random.default_rng(seed)
    lo = np.full(dim, -0.2)
    hi = lo + np.array([1.03, 0.77, 0.55][:dim])
    pos = np.zeros((capacity, dim))
    # uniform over the box grown by 0.05 on each side: some points fall outside it
    pos[:n] = rng.uniform(lo - 0.05, hi + 0.05, size=(n, dim))
    # three dense clumps (10 % of the points within 0.02 of a centre): crowded cells
    clump = np.nonzero(rng.random(n) < 0.1)[0]
    centres = rng.uniform(lo + 0.1, hi - 0.1, size=(3, dim))
    pos[clump] = centres[clump % 3] + rng.uniform(-0.02, 0.02, size=(len(clump), dim))
    pos[3] = np.nan  # a broken position counts as outside
    pos[4] = hi  # hi itself is outside [lo, hi)
    pos[5] = lo  # lo is inside
    active = np.zeros(capacity, dtype=np.int32)
    active[:n] = rng.random(n) < 0.9
    active[3:6] = 1
    mask = np.zeros(capacity, dtype=np.int8)
    mask[:n] = rng.random(n) < 0.8
    return lo, hi, pos, active, mask


def make_fields(dim, capacity, pos, active, mask):
    x = ti.Vector.field(dim, float, capacity)
    act = ti.field(ti.i32, capacity)
    msk = ti.field(ti.i8, capacity)
    ids = ti.field(ti.i32, capacity)
    x.from_numpy(pos)
    act.from_numpy(active)
    msk.from_numpy(mask)
    ids.from_numpy(np.arange(capacity, dtype=np.int32) + 1000)
    return x, act, msk, ids


def expected_outside(pos, active, lo, hi, n):
    with np.errstate(invalid="ignore"):
        inside = np.all((pos[:n] >= lo) & (pos[:n] < hi), axis=1)
    return np.nonzero((active[:n] != 0) & ~inside)[0]


def brute_force(pos, in_grid, rows, radius):
    """Neighbour sets by a k-d tree, filtered with the same strict test |d|^2 < r^2 as the grid."""
    cand = np.nonzero(in_grid)[0]
    tree = cKDTree(pos[cand])
    out = {}
    for i in np.nonzero(rows)[0]:
        js = cand[tree.query_ball_point(pos[i], radius * (1 + 1e-9))]
        d = pos[js] - pos[i]
        js = js[(np.sum(d * d, axis=1) < radius * radius) & (js != i)]
        out[int(i)] = set(js.tolist())
    return out


@pytest.mark.parametrize("dim, n, serial", [(2, 3000, False), (3, 4000, False), (2, 3000, True)])
def test_neighbour_lists_match_brute_force(ti_cpu, dim, n, serial):
    """`serial`: every loop of the grid on the calling thread (a solver's small scene on the CPU)."""
    capacity = n + 37
    lo, hi, pos, active, mask = make_case(dim, n, capacity, seed=dim)
    x, act, msk, ids = make_fields(dim, capacity, pos, active, mask)
    grid = NeighbourGrid(capacity, dim, lo, hi, CELL, max_neighbours=400, serial=serial)
    assert grid.serial_loops == serial
    assert grid.ncell == tuple(int(np.ceil((hi[d] - lo[d]) / CELL)) for d in range(dim))
    assert grid.num_cells == int(np.prod(grid.ncell))

    left = grid.sort(x, act, n)
    out = expected_outside(pos, active, lo, hi, n)
    assert 3 in left and 4 in left and 5 not in left
    np.testing.assert_array_equal(left, out)
    assert len(out) > 20
    active_after = active.copy()
    active_after[out] = 0
    np.testing.assert_array_equal(act.to_numpy(), active_after)

    # perm is a permutation; cells ascend along it; within a cell original indices ascend
    perm = grid.perm.to_numpy()[:n]
    np.testing.assert_array_equal(np.sort(perm), np.arange(n))
    start = grid.cell_start.to_numpy()
    assert start[0] == 0 and np.all(np.diff(start) >= 0) and start[-1] == int(active_after[:n].sum())
    cell_of = np.full(n, grid.num_cells)
    for c in range(grid.num_cells):
        cell_of[perm[start[c]:start[c + 1]]] = c
    assert np.all(cell_of[active_after[:n] == 0] == grid.num_cells)
    real = active_after[:n] != 0
    ijk = np.floor((pos[:n][real] - lo) / CELL).astype(int)
    np.testing.assert_array_equal(cell_of[real], np.ravel_multi_index(ijk.T, grid.ncell))
    keys = cell_of[perm] * n + perm
    assert np.all(np.diff(keys) > 0)

    for f in (x, act, msk, ids):
        grid.reorder(f, n)
    grid.build_neighbour_lists(x, msk, n, RADIUS, ids=ids)

    spos = pos[:n][perm]
    in_grid = active_after[:n][perm] != 0
    rows = (mask[:n][perm] != 0) & in_grid
    expect = brute_force(spos, in_grid, rows, RADIUS)
    count = grid.nbr_count.to_numpy()[:n]
    nbr = grid.nbr.to_numpy()[:n]
    assert np.all(count[~rows] == 0)
    for i, js in expect.items():
        got = nbr[i, : count[i]]
        assert np.all(np.diff(got) > 0)  # each row is built by one thread: ascending j
        assert set(got.tolist()) == js, f"row {i}"
    assert sum(len(s) for s in expect.values()) > 10 * len(expect)  # not a trivially sparse case
    assert grid.max_count(n) == max(len(s) for s in expect.values())

    # sorting the sorted data again: nothing leaves, the cells are already in order
    assert grid.sort(x, act, n).size == 0
    np.testing.assert_array_equal(grid.perm.to_numpy()[:n], np.arange(n))


def test_grouped_lists_order_each_row_by_group(ti_cpu):
    """A grouped grid's lists hold the same neighbours as the plain build, in group order 0, 1, 2 (each group
    in the plain list's order), and nbr_split gives where groups 1 and 2 start. group_rows (a checkpoint's
    restore) keeps grouped lists as they are and puts a list saved ungrouped in group order."""
    dim, n = 2, 3000
    capacity = n + 11
    lo, hi, pos, active, mask = make_case(dim, n, capacity, seed=7)
    x, act, msk, ids = make_fields(dim, capacity, pos, active, mask)
    group = ti.field(ti.i32, capacity)
    groups = np.random.default_rng(3).integers(0, 3, capacity).astype(np.int32)
    group.from_numpy(groups)
    plain = NeighbourGrid(capacity, dim, lo, hi, CELL, max_neighbours=400)
    grouped = NeighbourGrid(capacity, dim, lo, hi, CELL, max_neighbours=400, grouped=True)
    plain.sort(x, act, n)
    plain.build_neighbour_lists(x, msk, n, RADIUS, in_place=False)
    grouped.sort(x, act, n)
    with pytest.raises(ValueError, match="group"):
        grouped.build_neighbour_lists(x, msk, n, RADIUS, in_place=False)
    grouped.build_neighbour_lists(x, msk, n, RADIUS, in_place=False, group=group)
    count = plain.nbr_count.to_numpy()[:n]
    np.testing.assert_array_equal(grouped.nbr_count.to_numpy()[:n], count)
    before = plain.nbr.to_numpy()
    after = grouped.nbr.to_numpy()
    split = grouped.nbr_split.to_numpy()[:n]
    rows = np.nonzero(count > 0)[0]
    assert len(rows) > 1000
    for i in rows:
        row = before[i, : count[i]]
        expect = np.concatenate([row[groups[row] == g] for g in range(3)])
        np.testing.assert_array_equal(after[i, : count[i]], expect)
        assert tuple(split[i]) == (np.sum(groups[row] == 0), np.sum(groups[row] <= 1))
    # restore: grouped lists stay as they are, with their split
    grouped.nbr_split.fill(-1)
    grouped.group_rows(group, n)
    np.testing.assert_array_equal(grouped.nbr.to_numpy(), after)
    np.testing.assert_array_equal(grouped.nbr_split.to_numpy()[:n], split)
    # restore of lists saved ungrouped: the same sets, in group order, with their split
    grouped.nbr.from_numpy(before)
    grouped.group_rows(group, n)
    regrouped = grouped.nbr.to_numpy()
    np.testing.assert_array_equal(grouped.nbr_split.to_numpy()[:n], split)
    for i in rows:
        got = regrouped[i, : count[i]]
        assert np.all(np.diff(groups[got]) >= 0)
        np.testing.assert_array_equal(np.sort(got), np.sort(before[i, : count[i]]))
    with pytest.raises(RuntimeError, match="grouped=True"):
        plain.group_rows(group, n)


def test_overflow_names_particle(ti_cpu):
    dim, n = 2, 3000
    capacity = n + 37
    lo, hi, pos, active, mask = make_case(dim, n, capacity, seed=2)
    x, act, msk, ids = make_fields(dim, capacity, pos, active, mask)
    grid = NeighbourGrid(capacity, dim, lo, hi, CELL, max_neighbours=5)
    grid.sort(x, act, n)
    perm = grid.perm.to_numpy()[:n]
    for f in (x, act, msk, ids):
        grid.reorder(f, n)

    with pytest.raises(NeighbourOverflowError) as info:
        grid.build_neighbour_lists(x, msk, n, RADIUS, ids=ids)
    err = info.value
    in_grid = act.to_numpy()[:n] != 0
    rows = (msk.to_numpy()[:n] != 0) & in_grid
    expect = brute_force(pos[:n][perm], in_grid, rows, RADIUS)
    true_counts = {i: len(s) for i, s in expect.items()}
    worst = max(true_counts.values())
    assert err.capacity == 5
    assert err.count == worst == true_counts[err.index]
    assert err.particle_id == 1000 + perm[err.index]
    msg = str(err)
    assert "\n" not in msg
    assert str(err.particle_id) in msg and str(err.count) in msg and "5" in msg
    assert "neighbours.max" in msg
    # the lists hold at most max_neighbours entries, all of them true neighbours
    count = grid.nbr_count.to_numpy()[:n]
    nbr = grid.nbr.to_numpy()[:n]
    assert count.max() == 5
    for i, js in expect.items():
        assert count[i] == min(len(js), 5)
        assert set(nbr[i, : count[i]].tolist()) <= js

    # without ids the index is named
    with pytest.raises(NeighbourOverflowError) as info:
        grid.build_neighbour_lists(x, msk, n, RADIUS)
    assert info.value.particle_id is None and info.value.index == err.index
    assert f"index {err.index}" in str(info.value)


def test_reorder_moves_fields_consistently(ti_cpu):
    dim, n, capacity = 3, 500, 520
    rng = np.random.default_rng(7)
    lo, hi = np.zeros(3), np.ones(3)
    pos = rng.uniform(0.0, 1.0, size=(capacity, dim))
    x = ti.Vector.field(dim, float, capacity)
    act = ti.field(ti.i32, capacity)
    x.from_numpy(pos)
    act.fill(1)
    grid = NeighbourGrid(capacity, dim, lo, hi, 0.25, max_neighbours=8)
    assert grid.sort(x, act, n).size == 0
    perm = grid.perm.to_numpy()[:n]
    assert not np.array_equal(perm, np.arange(n))

    s = ti.field(float, capacity)
    v = ti.Vector.field(dim, float, capacity)
    k = ti.field(ti.i32, capacity)
    m = ti.Matrix.field(2, 3, ti.f32, capacity)
    s2 = ti.field(float, capacity)  # a second field of the same kind shares the scratch field
    data = {
        s: rng.normal(size=capacity),
        v: rng.normal(size=(capacity, dim)),
        k: np.arange(capacity, dtype=np.int32) * 3,
        m: rng.normal(size=(capacity, 2, 3)).astype(np.float32),
        s2: rng.normal(size=capacity),
    }
    for f, a in data.items():
        f.from_numpy(a)
        grid.reorder(f, n)
    for f, a in data.items():
        got = f.to_numpy()
        np.testing.assert_array_equal(got[:n], a[:n][perm])
        np.testing.assert_array_equal(got[n:], a[n:])  # entries past n untouched

    with pytest.raises(ValueError):
        grid.reorder(s, n - 1)  # the permutation belongs to the last sort(n)


def test_sort_is_deterministic(ti_cpu):
    dim, n = 3, 4000
    lo, hi, pos, active, mask = make_case(dim, n, n, seed=11)
    perms = []
    for _ in range(2):
        x, act, _, _ = make_fields(dim, n, pos, active, mask)
        grid = NeighbourGrid(n, dim, lo, hi, CELL, max_neighbours=400)
        left = grid.sort(x, act, n)
        perms.append((grid.perm.to_numpy().copy(), grid.cell_start.to_numpy().copy(), left))
    for a, b in zip(perms[0], perms[1]):
        np.testing.assert_array_equal(a, b)


def test_radius_larger_than_cell_rejected(ti_cpu):
    dim, n = 2, 100
    lo, hi, pos, active, mask = make_case(dim, n, n, seed=5)
    x, act, msk, _ = make_fields(dim, n, pos, active, mask)
    grid = NeighbourGrid(n, dim, lo, hi, CELL, max_neighbours=400)
    grid.sort(x, act, n)
    with pytest.raises(ValueError, match="cell size"):
        grid.build_neighbour_lists(x, msk, n, CELL * 1.01)


def test_blocked_scan_gives_the_serial_sort(ti_cpu, monkeypatch):
    """The blocked prefix sum (the GPU's, forced here on the CPU) gives the cells' starts and the sort's
    permutation of the serial one, integer for integer."""
    from taichi_sph.sph import scan

    dim, n = 3, 4000
    lo, hi, pos, active, mask = make_case(dim, n, n, seed=11)
    out = []
    for blocked in (False, True):
        monkeypatch.setattr(scan, "on_cpu", lambda b=blocked: not b)
        x, act, _, _ = make_fields(dim, n, pos, active, mask)
        grid = NeighbourGrid(n, dim, lo, hi, CELL, max_neighbours=400)
        assert grid._scan.blocked == blocked
        left = grid.sort(x, act, n)
        out.append((grid.perm.to_numpy().copy(), grid.cell_start.to_numpy().copy(), left))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("n", [0, 1, 127, 128, 129, 1000, 4097])
def test_prefix_sum_against_numpy(ti_cpu, n):
    """Both forms of PrefixSum against numpy's cumulative sum, at block edges (the block is 128 here) and for
    no counts at all; the copy receives the same values."""
    from taichi_sph.sph.scan import PrefixSum

    cap = 4097
    count = ti.field(ti.i32, cap)
    rng = np.random.default_rng(n)
    counts = rng.integers(0, 9, cap).astype(np.int32)
    count.from_numpy(counts)
    want = np.concatenate([[0], np.cumsum(counts[:n])])
    for blocked in (False, True):
        ps = PrefixSum(cap, blocked=blocked)
        start = ti.field(ti.i32, cap + 1)
        copy = ti.field(ti.i32, cap + 1)

        @ti.kernel
        def run(m: ti.i32):
            ps.exclusive_with_copy(count, start, m, copy)

        run(n)
        np.testing.assert_array_equal(start.to_numpy()[: n + 1], want)
        np.testing.assert_array_equal(copy.to_numpy()[: n + 1], want)
        alone = ti.field(ti.i32, cap + 1)

        @ti.kernel
        def run_alone(m: ti.i32):
            ps.exclusive(count, alone, m)

        run_alone(n)
        np.testing.assert_array_equal(alone.to_numpy()[: n + 1], want)
