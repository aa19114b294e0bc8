"""Uniform-grid neighbour search shared by both solver modes.

Particles are binned into cubic cells of edge `cell_size` covering the box [lo, hi) and ordered by
cell with a counting sort: per-cell counts (atomic), an exclusive prefix sum over the cells and a
scatter into `perm`. A counting sort has no per-cell capacity, so a cell can never overflow however
many particles crowd into it. Inactive particles and particles outside [lo, hi) go to a sentinel
cell `num_cells` after all real cells; `sort()` deactivates particles that were active but left the
box and returns their indices.

On CPU the scan and the scatter run serially (``ti.loop_config(serialize=True)``): within a cell the
particles keep ascending original index, so `perm` is deterministic. On GPU the scatter is atomic and
the order inside a cell may vary from run to run. The scan over the cells is serial on the CPU and
blocked on GPUs (scan.py). A grid made with `serial=True` (a solver's small scene on the CPU) runs all its
loops serially: Taichi's thread pool costs more than a few thousand particles' work.

`sort()` only computes `perm`; `reorder()` applies it to any per-particle field. After sorting and
reordering positions, `build_neighbour_lists()` writes an explicit neighbour list per particle by
scanning the 3^dim cells around it. A grid made with `grouped=True` builds each list ordered by a
per-particle group 0, 1, 2 (the cells scanned once per group, each group in the plain list's order) and
keeps where groups 1 and 2 start (`nbr_split`): mode wcsph_biot lists soil, walls, fluid, so that a pass
over one set skips the others without reading them. `group_rows` sets `nbr_split` for lists restored
from a checkpoint (and groups, in place, a list saved ungrouped).

Periodic axes (`period`, the period L of each axis, 0 where the axis is not periodic) span [0, L)
whatever `lo` and `hi` say: their cell count is floor(L / cell_size), so a cell is at least the
search radius, and at least 3 (with fewer, the cells on either side of a cell would be one and the same,
and a pair would be listed twice). Cells wrap around those axes, `sort()` wraps positions past L back
into [0, L) (they are not deactivated), and distances use the minimum image (`operators.rel`).
"""

import math

import numpy as np
import taichi as ti

from ..backend import on_cpu
from .operators import rel, wrap
from .scan import PrefixSum


class NeighbourOverflowError(RuntimeError):
    """A particle has more neighbours than the neighbour list can hold."""

    def __init__(self, index: int, particle_id: int | None, count: int, capacity: int, rows: int = 1):
        self.index = int(index)
        self.particle_id = None if particle_id is None else int(particle_id)
        self.count = int(count)
        self.capacity = int(capacity)
        self.rows = int(rows)
        who = f"particle id {self.particle_id}" if self.particle_id is not None else f"particle index {self.index}"
        others = f" ({self.rows} particles over the limit)" if self.rows > 1 else ""
        super().__init__(
            f"{who} has {self.count} neighbours but the neighbour list holds {self.capacity}{others}; "
            f"raise the config key `neighbours.max` to at least {self.count}"
        )


@ti.data_oriented
class NeighbourGrid:
    """Cell grid, counting sort and explicit neighbour lists for up to `capacity` particles."""

    def __init__(self, capacity: int, dim: int, lo, hi, cell_size: float, max_neighbours: int, period=None,
                 grouped: bool = False, serial: bool = False):
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, not {dim}")
        lo = np.asarray(lo, dtype=float).reshape(-1).copy()
        hi = np.asarray(hi, dtype=float).reshape(-1).copy()
        if lo.size != dim or hi.size != dim:
            raise ValueError(f"lo and hi need {dim} components, got {lo.size} and {hi.size}")
        period = tuple(float(v) for v in (period if period is not None else [0.0] * dim))
        if len(period) != dim or any(not (v >= 0.0) for v in period):
            raise ValueError(f"period needs {dim} values >= 0 (0 = not periodic), got {period}")
        for d in range(dim):
            if period[d] > 0.0:
                lo[d], hi[d] = 0.0, period[d]
        if not np.all(hi > lo):
            raise ValueError(f"grid box is empty: lo={lo.tolist()}, hi={hi.tolist()}")
        if not cell_size > 0.0:
            raise ValueError(f"cell_size must be positive, not {cell_size}")
        if capacity < 1 or max_neighbours < 1:
            raise ValueError("capacity and max_neighbours must be at least 1")
        self.dim = int(dim)
        self.capacity = int(capacity)
        self.cell_size = float(cell_size)
        self.max_neighbours = int(max_neighbours)
        self.lo = lo
        self.hi = hi
        self.period = period
        self._any_periodic = any(v > 0.0 for v in period)
        self.ncell = tuple(int(period[d] // self.cell_size) if period[d] > 0.0
                           else max(1, int(math.ceil((hi[d] - lo[d]) / self.cell_size))) for d in range(dim))
        for d in range(dim):
            if period[d] > 0.0 and self.ncell[d] < 3:
                raise ValueError(f"periodic axis {d}: the period {period[d]:g} must hold at least 3 cells of "
                                 f"{self.cell_size:g} (the neighbour search radius)")
        # cell edge per axis: cell_size, or L / ncell (>= cell_size) along periodic axes
        self._edge = [period[d] / self.ncell[d] if period[d] > 0.0 else self.cell_size for d in range(dim)]
        self.num_cells = int(np.prod(self.ncell))
        # python floats/ints for ti.static use inside kernels
        self._lo = [float(v) for v in lo]
        self._hi = [float(v) for v in hi]
        self._serial = on_cpu()
        #: every loop runs on the calling thread (the solver's flag for a small scene on the CPU); else only
        #: the scatter does, on the CPU (above)
        self.serial_loops = bool(serial) and self._serial

        self.perm = ti.field(ti.i32, self.capacity)
        self.cell_start = ti.field(ti.i32, self.num_cells + 1)
        self.nbr_count = ti.field(ti.i32, self.capacity)
        self.nbr = ti.field(ti.i32, (self.capacity, self.max_neighbours))
        self._cell = ti.field(ti.i32, self.capacity)  # cell of particle i, original order
        self._cell_sorted = ti.field(ti.i32, self.capacity)  # cell of position k, sorted order
        #: cell of the particle at (sorted) index k after `sort()`, `num_cells` outside the box or inactive
        self.cell = self._cell_sorted
        self._left = ti.field(ti.i8, self.capacity)  # 1 if deactivated by the last sort()
        self._count = ti.field(ti.i32, self.num_cells + 1)
        self._cursor = ti.field(ti.i32, self.num_cells + 1)
        self._scan = PrefixSum(self.num_cells)
        self._raw_count = ti.field(ti.i32, self.capacity)  # true neighbour count, not clamped
        self._ovf_max = ti.field(ti.i32, ())
        self._ovf_rows = ti.field(ti.i32, ())
        self._ovf_index = ti.field(ti.i32, ())
        self._scratch = {}
        self._sorted_n = None
        #: `grouped`: each list is ordered by the neighbours' group (0, 1, 2), and `nbr_split[i]` keeps where
        #: groups 1 and 2 start, so that a pass that needs some groups walks only their range
        self.grouped = bool(grouped)
        self.nbr_split = ti.Vector.field(2, ti.i32, self.capacity if grouped else 1)
        self._no_group = ti.field(ti.i32, 1)  # the group argument of an ungrouped build

    # ------------------------------------------------------------------ sort
    @ti.kernel
    def _bin(self, x: ti.template(), active: ti.template(), n: ti.i32) -> ti.i32:
        ti.loop_config(serialize=self.serial_loops)
        for c in range(self.num_cells + 1):
            self._count[c] = 0
        left = 0
        ti.loop_config(serialize=self.serial_loops)
        for i in range(n):
            c = self.num_cells
            self._left[i] = ti.i8(0)
            if active[i] != 0:
                inside = 1
                lin = 0
                if ti.static(self._any_periodic):
                    x[i] = wrap(x[i], ti.static(self.period))
                for d in ti.static(range(self.dim)):
                    p = x[i][d]
                    # NaN fails both comparisons and counts as outside
                    if not (p >= ti.static(self._lo[d]) and p < ti.static(self._hi[d])):
                        inside = 0
                    ic = 0
                    if inside:
                        ic = ti.min(ti.cast((p - ti.static(self._lo[d])) / ti.static(self._edge[d]), ti.i32),
                                    ti.static(self.ncell[d] - 1))
                    lin = lin * ti.static(self.ncell[d]) + ic
                if inside:
                    c = lin
                else:
                    active[i] = ti.cast(0, active.dtype)
                    self._left[i] = ti.i8(1)
                    left += 1
            self._cell[i] = c
            ti.atomic_add(self._count[c], 1)
        return left

    @ti.kernel
    def _scan_scatter(self, n: ti.i32):
        self._scan.exclusive_with_copy(self._count, self.cell_start, ti.static(self.num_cells), self._cursor)
        if ti.static(self._serial):
            ti.loop_config(serialize=True)
            for i in range(n):
                c = self._cell[i]
                k = self._cursor[c]
                self._cursor[c] = k + 1
                self.perm[k] = i
                self._cell_sorted[k] = c
        else:
            for i in range(n):
                c = self._cell[i]
                k = ti.atomic_add(self._cursor[c], 1)
                self.perm[k] = i
                self._cell_sorted[k] = c

    def sort(self, x, active, n: int) -> np.ndarray:
        """Bin the first `n` particles and compute `perm` (new position k holds old particle perm[k]).

        Active particles outside [lo, hi) (or with non-finite positions) are set inactive. Returns
        their original indices (usually empty). Moves no data: call `reorder()` on each field.
        """
        n = int(n)
        if not 0 <= n <= self.capacity:
            raise ValueError(f"n={n} outside [0, capacity={self.capacity}]")
        left = self._bin(x, active, n)
        self._scan_scatter(n)
        self._sorted_n = n
        if left == 0:
            return np.zeros(0, dtype=np.int64)
        return np.nonzero(self._left.to_numpy()[:n])[0].astype(np.int64)

    # --------------------------------------------------------------- reorder
    @ti.kernel
    def _gather(self, src: ti.template(), tmp: ti.template(), n: ti.i32):
        ti.loop_config(serialize=self.serial_loops)
        for k in range(n):
            p = self.perm[k]
            if ti.static(len(src.shape) == 1):
                tmp[k] = src[p]
            else:
                for j in range(src.shape[1]):
                    tmp[k, j] = src[p, j]
        ti.loop_config(serialize=self.serial_loops)
        for k in range(n):
            if ti.static(len(src.shape) == 1):
                src[k] = tmp[k]
            else:
                for j in range(src.shape[1]):
                    src[k, j] = tmp[k, j]

    def _scratch_for(self, field):
        shape = tuple(field.shape)
        if isinstance(field, ti.MatrixField):
            if field.ndim == 1:
                key = ("vec", field.dtype, (field.n,), shape)
            else:
                key = ("mat", field.dtype, (field.n, field.m), shape)
        elif isinstance(field, ti.ScalarField):
            key = ("scalar", field.dtype, (), shape)
        else:
            raise TypeError(f"reorder() needs a Taichi field, got {type(field).__name__}")
        tmp = self._scratch.get(key)
        if tmp is None:
            kind, dtype, elem, _ = key
            if kind == "vec":
                tmp = ti.Vector.field(elem[0], dtype, shape)
            elif kind == "mat":
                tmp = ti.Matrix.field(elem[0], elem[1], dtype, shape)
            else:
                tmp = ti.field(dtype, shape)
            self._scratch[key] = tmp
        return tmp

    def reorder(self, field, n: int):
        """Permute a per-particle field in place: field[k] = old field[perm[k]] for k < n."""
        n = int(n)
        if self._sorted_n is None:
            raise RuntimeError("reorder() called before sort()")
        if n != self._sorted_n:
            raise ValueError(f"reorder(n={n}) does not match the last sort(n={self._sorted_n})")
        shape = tuple(field.shape)
        if len(shape) not in (1, 2) or shape[0] < n:
            raise ValueError(f"cannot reorder a field of shape {shape} with n={n}")
        self._gather(field, self._scratch_for(field), n)

    # ------------------------------------------------------- neighbour lists
    @ti.kernel
    def _build(self, x: ti.template(), mask: ti.template(), n: ti.i32, radius: float,
               in_place: ti.template(), group: ti.template()) -> ti.i32:
        """in_place: the particle arrays are in cell order (`reorder` applied); else particle perm[k] sits at
        its own index and the cells are walked through perm. A grouped grid scans the cells once per group
        of `group` and records where groups 1 and 2 start."""
        self._ovf_max[None] = 0
        r2max = radius * radius
        overflow = 0
        ti.loop_config(serialize=self.serial_loops)
        for i in range(n):
            cnt = 0
            s0 = 0
            s1 = 0
            c = self._cell_sorted[i]
            if ti.static(not in_place):
                c = self._cell[i]
            if mask[i] != 0 and c < self.num_cells:
                # cell coordinates, last axis fastest
                cc = ti.Vector.zero(ti.i32, ti.static(self.dim))
                rest = c
                for d in ti.static(range(self.dim - 1, -1, -1)):
                    cc[d] = rest % ti.static(self.ncell[d])
                    rest = rest // ti.static(self.ncell[d])
                # along the last axis the 3 neighbouring cells are consecutive, so each row of cells
                # is one contiguous particle range [cell_start[first], cell_start[last + 1])
                # (a periodic last axis takes its 3 cells one by one: they need not be consecutive)
                last = ti.static(self.dim - 1)
                zlo = ti.max(cc[last] - 1, 0)
                zhi = ti.min(cc[last] + 1, ti.static(self.ncell[last] - 1))
                xi = x[i]
                for g in ti.static(range(3 if self.grouped else 1)):  # one scan per group
                    for off in ti.static(ti.grouped(ti.ndrange(*([(-1, 2)] * (self.dim - 1))))):
                        ok = 1
                        lin = 0
                        for d in ti.static(range(self.dim - 1)):
                            nd = cc[d] + off[d]
                            if ti.static(self.period[d] > 0.0):
                                nd = (nd + ti.static(self.ncell[d])) % ti.static(self.ncell[d])
                            if nd < 0 or nd >= ti.static(self.ncell[d]):
                                ok = 0
                            lin = lin * ti.static(self.ncell[d]) + nd
                        if ok:
                            lin = lin * ti.static(self.ncell[last])
                            for zo in ti.static(range(1 if self.period[last] == 0.0 else 3)):
                                a = lin + zlo
                                b = lin + zhi + 1
                                if ti.static(self.period[last] > 0.0):
                                    z = (cc[last] + zo - 1 + ti.static(self.ncell[last])) % ti.static(self.ncell[last])
                                    a = lin + z
                                    b = lin + z + 1
                                for k in range(self.cell_start[a], self.cell_start[b]):
                                    j = k
                                    if ti.static(not in_place):
                                        j = self.perm[k]
                                    same = True
                                    if ti.static(self.grouped):
                                        same = group[j] == g
                                    if j != i and same:
                                        dx = rel(xi, x[j], ti.static(self.period))
                                        if dx.dot(dx) < r2max:
                                            if cnt < ti.static(self.max_neighbours):
                                                self.nbr[i, cnt] = j
                                            cnt += 1
                    if ti.static(g == 0):
                        s0 = cnt
                    if ti.static(g == 1):
                        s1 = cnt
            self._raw_count[i] = cnt
            if cnt > ti.static(self.max_neighbours):
                overflow += 1
                ti.atomic_max(self._ovf_max[None], cnt)
            self.nbr_count[i] = ti.min(cnt, ti.static(self.max_neighbours))
            if ti.static(self.grouped):
                self.nbr_split[i] = ti.Vector([ti.min(s0, ti.static(self.max_neighbours)),
                                               ti.min(s1, ti.static(self.max_neighbours))])
        return overflow

    @ti.kernel
    def _find_overflow(self, n: ti.i32):
        self._ovf_index[None] = n
        ti.loop_config(serialize=self.serial_loops)
        for i in range(n):
            if self._raw_count[i] == self._ovf_max[None]:
                ti.atomic_min(self._ovf_index[None], i)

    def build_neighbour_lists(self, x, mask, n: int, radius: float, ids=None, in_place: bool = True,
                              group=None):
        """Fill `nbr` / `nbr_count` for rows i < n with mask[i] != 0: all j != i with |x_i - x_j| < radius.

        Call after `sort()` and `reorder()` of `x` and `mask`; or, with `in_place=False`, after `sort()` alone
        (the particles keep their indices, the lists are the same sets in another order). Rows with mask 0,
        and particles in the sentinel cell, get no neighbours. Raises NeighbourOverflowError (naming the
        particle with the most neighbours, `ids[index]` when `ids` is given) if a row exceeds `max_neighbours`.
        """
        n = int(n)
        radius = float(radius)
        if self._sorted_n is None:
            raise RuntimeError("build_neighbour_lists() called before sort()")
        if n != self._sorted_n:
            raise ValueError(f"build_neighbour_lists(n={n}) does not match the last sort(n={self._sorted_n})")
        if not 0.0 < radius <= self.cell_size:
            raise ValueError(f"radius {radius} must be positive and at most the cell size {self.cell_size}")
        if self.grouped and group is None:
            raise ValueError("a grouped grid builds its lists with the particles' group (group=...)")
        rows = self._build(x, mask, n, radius, bool(in_place), group if self.grouped else self._no_group)
        if rows > 0:
            self._find_overflow(n)
            index = int(self._ovf_index[None])
            count = int(self._ovf_max[None])
            pid = int(ids[index]) if ids is not None else None
            raise NeighbourOverflowError(index, pid, count, self.max_neighbours, rows)

    @ti.func
    def cell_range(self, point, off):
        """Particle index range [a, b) of the cell `off` (integer offsets per axis) away from the cell that
        holds `point`, in the sorted order of the last `sort()` with `reorder` applied; an empty range where
        that cell lies outside the grid (periodic axes wrap)."""
        lin = 0
        ok = 1
        for d in ti.static(range(self.dim)):
            c = ti.cast(ti.floor((point[d] - ti.static(self._lo[d])) / ti.static(self._edge[d])), ti.i32)
            c += off[d]
            if ti.static(self.period[d] > 0.0):
                c = (c % ti.static(self.ncell[d]) + ti.static(self.ncell[d])) % ti.static(self.ncell[d])
            if c < 0 or c >= ti.static(self.ncell[d]):
                ok = 0
            lin = lin * ti.static(self.ncell[d]) + ti.min(ti.max(c, 0), ti.static(self.ncell[d] - 1))
        a = 0
        b = 0
        if ok:
            a = self.cell_start[lin]
            b = self.cell_start[lin + 1]
        return a, b

    @ti.func
    def cell_gap2(self, point, off):
        """Squared distance from `point` to the nearest point of the cell `off` (integer offsets per axis)
        away from the cell that holds it: a search reaching farther than one cell skips the cells that lie
        wholly beyond its radius."""
        gap2 = 0.0
        for d in ti.static(range(self.dim)):
            edge = ti.static(self._edge[d])
            c = ti.floor((point[d] - ti.static(self._lo[d])) / edge)
            lo_d = ti.static(self._lo[d]) + (c + off[d]) * edge
            g = 0.0
            if off[d] > 0:
                g = lo_d - point[d]
            elif off[d] < 0:
                g = point[d] - (lo_d + edge)
            gap2 += g * g
        return gap2

    @ti.kernel
    def _group_rows(self, group: ti.template(), n: ti.i32):
        ti.loop_config(serialize=self.serial_loops)
        for i in range(n):
            cnt = self.nbr_count[i]
            grouped = True
            for k in range(1, cnt):
                if group[self.nbr[i, k]] < group[self.nbr[i, k - 1]]:
                    grouped = False
            if not grouped:
                # a list saved ungrouped: three-way partition in place (not stable, but deterministic)
                lo = 0
                mid = 0
                hi = cnt - 1
                while mid <= hi:
                    j = self.nbr[i, mid]
                    g = group[j]
                    if g == 0:
                        self.nbr[i, mid] = self.nbr[i, lo]
                        self.nbr[i, lo] = j
                        lo += 1
                        mid += 1
                    elif g == 1:
                        mid += 1
                    else:
                        self.nbr[i, mid] = self.nbr[i, hi]
                        self.nbr[i, hi] = j
                        hi -= 1
            c0 = 0
            c1 = 0
            for k in range(cnt):
                g = group[self.nbr[i, k]]
                if g == 0:
                    c0 += 1
                elif g == 1:
                    c1 += 1
            self.nbr_split[i] = ti.Vector([c0, c0 + c1])

    def group_rows(self, group, n: int):
        """Set `nbr_split` of the first n lists (restored from a checkpoint: the split is not saved) from the
        group of each neighbour (`group[j]` in 0, 1, 2); a list not in group order (saved by a code that did
        not group) is first put in group order in place. Lists in group order are left as they are. A grid
        built with `grouped`."""
        if not self.grouped:
            raise RuntimeError("group_rows() needs a grid built with grouped=True")
        self._group_rows(group, int(n))

    @ti.kernel
    def _max_count(self, n: ti.i32) -> ti.i32:
        m = 0
        ti.loop_config(serialize=self.serial_loops)
        for i in range(n):
            ti.atomic_max(m, self.nbr_count[i])
        return m

    def max_count(self, n: int) -> int:
        """Largest nbr_count over the first n rows."""
        return int(self._max_count(int(n)))
