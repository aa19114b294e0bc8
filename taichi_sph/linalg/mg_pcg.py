"""PPE solver in Taichi kernels: CG preconditioned by one multigrid V-cycle on the background cells.

The matrix is the ELL matrix of EllPCG (ell_pcg.py), filled by the same assembly (`start_row`, `add`,
`b`, `x`): only the preconditioner differs. Jacobi-PCG needs a number of iterations that grows with
the linear size of the water body (2D hydrostatic tank: 230 / 489 / 845 at 10k / 50k / 200k rows),
because a diagonal preconditioner moves information one neighbour shell per iteration. A multigrid
V-cycle carries the long-range part of the correction on coarse levels and keeps the count nearly
flat (geometric multigrid on the background cells of the neighbour search: Osaki, Morikawa & Asai,
PARTICLES 2023, for ISPH on a GPU).

Levels. Level 0 is the PPE itself, one row per water particle. Level 1 has one unknown per cell of
the neighbour grid (sph/grid.py, cell edge = the kernel support re): a cell aggregates the rows of the
water particles in it. Level l + 1 aggregates 2^dim cells of level l (cell coordinates halved), until
a level has at most MAX_COARSEST cells or at most 2 cells along every axis. Restriction is the sum over
an aggregate (particle-to-cell, then cell-to-parent), prolongation the injection of the aggregate's
value back to each member (cell-to-particle), i.e. the piecewise-constant P and R = P^T of plain
aggregation. Coarse operators are Galerkin products A_(l+1) = P^T A_l P, computed in kernels each
solve: no geometry or physics is re-derived on the cells, so the free-surface (Dirichlet) rows and the
wall (Neumann) rows are carried to every level exactly as the assembly wrote them (a Dirichlet row's
diagonal adds to its cell's diagonal, a Neumann wall adds nothing), and so are the jumps of the
coefficient k between free water and porous ground. A particle couples only with particles within re,
so a level-1 cell couples only with the 3^dim cells around it, and halving keeps that: every coarse
level is a 3^dim-point stencil on a regular grid of cells (stored densely per cell, empty cells with a
zero row and no work).

Cycle. Two damped-Jacobi sweeps before and two after the coarse correction on every level (weight
w_i = 1 / max(1.5 a_ii, 0.75 sum_j |a_ij|): 2/3 on the diagonally dominant rows of a PPE, and a
convergent smoother whatever the row), COARSEST_SWEEPS sweeps on the coarsest level, and the coarse
correction over-corrected by OVERCORRECTION: a piecewise-constant P makes P^T A P about twice as
stiff, per halving, as the operator the coarse grid should have, and scaling its correction by 2
restores the convergence of the cycle (aggregation with over-correction: Blaheta 1986; Braess 1995).
Measured on the jittered-lattice PPEs of tools/bench_ppe.py: PCG iterations to 1e-8 from zero
15 / 17 / 17 at 10k / 50k / 200k rows in 2D, 16 / 16 / 18 in 3D (Jacobi-PCG: 354 / 822 / - and
100 / 158 / -); the same cycle without over-correction, computed in scipy: 26 / 37 / 54 at 2.5k / 10k /
40k rows in 2D.

Why the V-cycle is a symmetric positive definite preconditioner (CG needs one): Jacobi is symmetric,
the post-smoothing repeats the pre-smoothing, R = P^T, and the coarse solve is itself such a cycle (a
fixed number of Jacobi sweeps on the coarsest level), so B = S_bar + (I - M A)^T alpha P B_c P^T (I - M A)
with the symmetrised smoother S_bar = M + M^T - M^T A M positive definite (the weights above make
2 M^-1 - A positive definite by Gershgorin) and the second term positive semidefinite for any alpha > 0.
tests/test_mg_pcg.py checks symmetry and positivity numerically.

Kernels. All cell levels live in flat fields (level l's cells at lev_start[l] ..), and every kernel
takes the level as a runtime argument, so each compiles once whatever the number of levels (a
kernel unrolled over levels and stencil slots took minutes to compile). In the V-cycle the two
pre-smoothing sweeps from zero are one loop (x = w (2 r - A (w r))), the residual is formed inside
the restriction and the prolongation inside the first post-smoothing sweep, so a level costs four
loops with five matrix-vector products in all. On a CPU, levels of fewer than SERIAL_BELOW cells run
together in one serial kernel (a parallel loop costs tens of microseconds to dispatch there, more than
their work), the others one parallel kernel per level and direction; on a GPU every level but the
coarsest runs parallel (one GPU thread is slow, a launch cheap). One CG iteration is then
the V-cycle's kernels (z = B r; r.z and beta stay on the device) and `EllPCG._k_iterate` without its
Jacobi step (p = z + beta p, A p with p.Ap, x and r updates, |r|^2 returned to the host).
The hierarchy is rebuilt in every solve (`_prepare`): rows binned by cell (a counting sort, serial on
CPU so that the order and the sums are deterministic), the Galerkin products and the weights; its cost
is in `last_setup_seconds`.
"""

import math
import time

import numpy as np
import taichi as ti

from ..backend import on_cpu
from ..sph.scan import PrefixSum
from .ell_pcg import STAGE_THREADS, EllPCG

#: factor on the coarse-grid correction of every level (see the module docstring)
OVERCORRECTION = 2.0
#: damped-Jacobi sweeps on the coarsest level (even, at least 2)
COARSEST_SWEEPS = 10
#: coarsening stops at this many cells (or at 2 cells along every axis)
MAX_COARSEST = 8
#: levels at most (a grid of 2^15 cells along an axis)
MAX_LEVELS = 16
#: cell levels with fewer cells run in one serial kernel
SERIAL_BELOW = 2048


@ti.data_oriented
class MGPCG(EllPCG):
    """A x = b, A symmetric positive definite in ELL form, CG preconditioned by a multigrid V-cycle whose
    levels are aggregates of background cells.

    cells: the number of level-1 cells along each axis; periodic: per axis, whether it wraps around.
    Each row must be given its level-1 cell (linear index, last axis fastest; -1 for a row that belongs
    to no cell, which must then have no off-diagonal entries): from a neighbour grid with `source =
    (cell, row)` (cell[k] the cell of particle k, `num_cells` or more outside; row[k] its row, -1 for
    none), read in every solve, or from the host with `load_cells`.
    """

    name = "mg_pcg"

    def __init__(self, n_max: int, max_nb: int, tolerance: float = 1.0e-8, max_iterations: int = 2000,
                 dtype=None, layout: str = "auto", *, cells, periodic=None, overcorrection: float = OVERCORRECTION,
                 source=None, reduction: str = "auto"):
        super().__init__(n_max, max_nb, tolerance, max_iterations, dtype, layout, reduction)
        dim = len(cells)
        if dim not in (1, 2, 3) or any(int(c) < 1 for c in cells):
            raise ValueError(f"cells must give 1 to 3 positive counts, not {cells}")
        self.dim = dim
        self.cells = tuple(int(c) for c in cells)
        self.periodic = tuple(bool(p) for p in (periodic if periodic is not None else [False] * dim))
        if len(self.periodic) != dim:
            raise ValueError(f"periodic needs {dim} flags, got {periodic}")
        if not overcorrection > 0.0:
            raise ValueError(f"overcorrection must be positive, not {overcorrection}")
        self.overcorrection = float(overcorrection)
        self.source = source
        dims = [self.cells]
        while math.prod(dims[-1]) > MAX_COARSEST and max(dims[-1]) > 2 and len(dims) < MAX_LEVELS:
            dims.append(tuple((d + 1) // 2 for d in dims[-1]))
        self.dims = dims
        self.m = len(dims)
        self.ncells = [math.prod(d) for d in dims]
        self.lev_start_np = np.concatenate([[0], np.cumsum(self.ncells)]).astype(np.int32)
        total = int(self.lev_start_np[-1])
        self.S = 3**dim
        self.center = (self.S - 1) // 2
        fp = self.dtype
        self.st = ti.field(fp)
        ti.root.dense(ti.i, total).dense(ti.j, self.S).place(self.st)
        self.w = ti.field(fp, total)
        self.gb = ti.field(fp, total)
        self.gx = ti.field(fp, total)
        self.gt = ti.field(fp, total)
        self.lev_start = ti.field(ti.i32, self.m + 1)
        self.lev_dim = ti.field(ti.i32, (self.m, dim))
        self.lev_start.from_numpy(self.lev_start_np)
        self.lev_dim.from_numpy(np.asarray(dims, dtype=np.int32).reshape(self.m, dim))
        n1 = self.ncells[0]
        self.agg = ti.field(ti.i32, self.n_max)
        self.rlist = ti.field(ti.i32, self.n_max)
        self.cstart = ti.field(ti.i32, n1 + 1)
        self.ccount = ti.field(ti.i32, n1 + 1)
        self.cursor = ti.field(ti.i32, n1 + 1)
        self.t0 = ti.field(fp, self.n_max)
        self.u0 = ti.field(fp, self.n_max)
        self.far_pairs = ti.field(ti.i32, ())
        self.agg.fill(-1)
        # cell levels 0 .. n_par - 1 run as parallel kernels, the rest (always the coarsest) in one serial one;
        # on a GPU, where a launch costs microseconds and one thread is slow, only the coarsest is serial
        cpu = on_cpu()
        n_par = 0
        while n_par < self.m - 1 and (self.ncells[n_par] >= SERIAL_BELOW or not cpu):
            n_par += 1
        self.n_par = n_par
        self._serial_scatter = cpu
        self._cell_scan = PrefixSum(n1)
        self._fresh = True
        self.last_setup_seconds = 0.0

    def with_width(self, max_nb: int) -> "MGPCG":
        other = MGPCG(self.n_max, max_nb, self.tolerance, self.max_iterations, self.dtype, self.layout,
                      cells=self.cells, periodic=self.periodic, overcorrection=self.overcorrection,
                      source=self.source, reduction=self.reduction)
        other.x.copy_from(self.x)
        other.agg.copy_from(self.agg)
        other.n[None] = self.n[None]
        return other

    def load_cells(self, cells) -> None:
        """Level-1 cell (linear index, last axis fastest; -1 none) of each of the first len(cells) rows,
        from the host (tests, tools); a solver with a `source` reads them in every solve instead."""
        a = np.full(self.n_max, -1, dtype=np.int32)
        c = np.asarray(cells, dtype=np.int64)
        a[: len(c)] = np.where((c >= 0) & (c < self.ncells[0]), c, -1)
        self.agg.from_numpy(a)

    # ------------------------------------------------------------------ cell grids
    @ti.func
    def _coords(self, l, c):
        """Cell coordinates of cell c (index within level l)."""
        cc = ti.Vector.zero(ti.i32, self.dim)
        rest = c
        for a in ti.static(range(self.dim - 1, -1, -1)):
            na = self.lev_dim[l, a]
            cc[a] = rest % na
            rest = rest // na
        return cc

    @ti.func
    def _coords1(self, c):
        """Cell coordinates of level-1 cell c, its grid's size known at compile time (divisions by
        constants: the Galerkin product at level 1 takes them once per matrix entry)."""
        cc = ti.Vector.zero(ti.i32, self.dim)
        rest = c
        for a in ti.static(range(self.dim - 1, -1, -1)):
            cc[a] = rest % ti.static(self.dims[0][a])
            rest = rest // ti.static(self.dims[0][a])
        return cc

    @ti.func
    def _child(self, CC, ch):
        """Coordinates of child ch (0 .. 2^dim - 1, one bit per axis, the first axis highest) of the
        coarse cell CC on the level below."""
        fc = 2 * CC
        for a in ti.static(range(self.dim)):
            fc[a] += (ch >> ti.static(self.dim - 1 - a)) & 1
        return fc

    @ti.func
    def _in_level(self, l, cc):
        """1 when the cell coordinates cc lie inside level l's grid (a coarse cell on an odd edge has
        fewer children), else 0."""
        inside = 1
        for a in ti.static(range(self.dim)):
            if cc[a] >= self.lev_dim[l, a]:
                inside = 0
        return inside

    @ti.func
    def _lin(self, l, cc):
        lin = 0
        for a in ti.static(range(self.dim)):
            lin = lin * self.lev_dim[l, a] + cc[a]
        return lin

    @ti.func
    def _ncoords(self, l, cc, k):
        """Coordinates of the cell in stencil slot k of cc on level l (wrapped on periodic axes);
        component 0 is -1 outside the grid."""
        nc = ti.Vector.zero(ti.i32, self.dim)
        ok = 1
        for a in ti.static(range(self.dim)):
            na = self.lev_dim[l, a]
            nd = cc[a] + (k // ti.static(3 ** (self.dim - 1 - a))) % 3 - 1
            if ti.static(self.periodic[a]):
                nd = (nd + na) % na
            elif nd < 0 or nd >= na:
                ok = 0
            nc[a] = nd
        if ok == 0:
            nc[0] = -1
        return nc

    @ti.func
    def _slot(self, l, cc, dd):
        """Stencil slot of the cell at coordinates dd seen from cc on level l (-1: more than a cell away)."""
        slot = 0
        ok = 1
        for a in ti.static(range(self.dim)):
            d = dd[a] - cc[a]
            if ti.static(self.periodic[a]):
                na = self.lev_dim[l, a]
                if d > 1:
                    d -= na
                elif d < -1:
                    d += na
            if d < -1 or d > 1:
                ok = 0
            slot = slot * 3 + d + 1
        out = -1
        if ok == 1:
            out = slot
        return out

    @ti.func
    def _g_av(self, l, base, v: ti.template(), c, cc):
        """(A_l v)_c on cell level l (c within the level, base its first flat index)."""
        s = ti.cast(0, self.dtype)
        for k in range(self.S):
            a = self.st[base + c, k]
            if a != 0:
                nc = self._ncoords(l, cc, k)
                s += a * v[base + self._lin(l, nc)]
        return s

    @ti.func
    def _g_awb(self, l, base, c, cc):
        """(A_l (w b))_c on cell level l: the first Jacobi sweep's result, formed on the fly."""
        s = ti.cast(0, self.dtype)
        for k in range(self.S):
            a = self.st[base + c, k]
            if a != 0:
                nb = base + self._lin(l, self._ncoords(l, cc, k))
                s += a * self.w[nb] * self.gb[nb]
        return s

    # ------------------------------------------------------------------ set-up (once per solve)
    @ti.kernel
    def _k_cells_from(self, cell: ti.template(), row: ti.template(), n_particles: ti.i32):
        for k in range(n_particles):
            r = row[k]
            if r >= 0:
                c = cell[k]
                if c < 0 or c >= ti.static(self.ncells[0]):
                    c = -1
                self.agg[r] = c

    @ti.kernel
    def _k_sort_rows(self):
        """rlist: the rows grouped by level-1 cell, rows of cell c at cstart[c] .. cstart[c + 1] - 1."""
        n = self.n[None]
        n1 = ti.static(self.ncells[0])
        for c in range(n1 + 1):
            self.ccount[c] = 0
        for i in range(n):
            c = self.agg[i]
            if c < 0:
                c = n1
            ti.atomic_add(self.ccount[c], 1)
        self._cell_scan.exclusive_with_copy(self.ccount, self.cstart, n1, self.cursor)
        if ti.static(self._serial_scatter):
            ti.loop_config(serialize=True)
        for i in range(n):
            c = self.agg[i]
            if c < 0:
                c = n1
            k = ti.atomic_add(self.cursor[c], 1)
            self.rlist[k] = i

    @ti.func
    def _weight(self, d, l1):
        s = ti.max(ti.cast(1.5, self.dtype) * d, ti.cast(0.75, self.dtype) * l1)
        out = ti.cast(0, self.dtype)
        if d > 0 and s > 0:
            out = 1 / s
        return out

    @ti.kernel
    def _k_galerkin0(self):
        """Smoothing weights of the rows, and A_1 = P^T A P on the level-1 cells."""
        n = self.n[None]
        zero = ti.cast(0, self.dtype)
        self.far_pairs[None] = 0
        for i in range(n):
            d = self.diag[i]
            l1 = ti.abs(d)
            for k in range(ti.min(self.count[i], self.max_nb)):
                l1 += ti.abs(self.vals[i, k])
            self.inv_diag[i] = self._weight(d, l1)
        for c in range(ti.static(self.ncells[0])):
            cc = self._coords1(c)
            for k in range(self.S):
                self.st[c, k] = zero
            for q in range(self.cstart[c], self.cstart[c + 1]):
                i = self.rlist[q]
                # (row c belongs to this iteration alone: a plain read and write, no atomic add)
                self.st[c, ti.static(self.center)] = self.st[c, ti.static(self.center)] + self.diag[i]
                for k in range(ti.min(self.count[i], self.max_nb)):
                    cj = self.agg[self.cols[i, k]]
                    if cj >= 0:
                        slot = self._slot(0, cc, self._coords1(cj))
                        if slot >= 0:
                            self.st[c, slot] = self.st[c, slot] + self.vals[i, k]
                        else:
                            ti.atomic_add(self.far_pairs[None], 1)

    @ti.kernel
    def _k_galerkin(self, l: ti.i32):
        """A_(l+1) = P^T A_l P (cell level l to l + 1)."""
        zero = ti.cast(0, self.dtype)
        fb = self.lev_start[l]
        cb = self.lev_start[l + 1]
        for C in range(self.lev_start[l + 2] - cb):
            CC = self._coords(l + 1, C)
            for k in range(self.S):
                self.st[cb + C, k] = zero
            for ch in range(ti.static(2**self.dim)):
                fc = self._child(CC, ch)
                if self._in_level(l, fc) == 1:
                    f = fb + self._lin(l, fc)
                    for k in range(self.S):
                        v = self.st[f, k]
                        if v != 0:
                            nc = self._ncoords(l, fc, k)
                            slot = self._slot(l + 1, CC, nc // 2)
                            self.st[cb + C, slot] = self.st[cb + C, slot] + v  # (row cb + C: this iteration's)

    @ti.kernel
    def _k_weights(self):
        for c in range(ti.static(int(self.lev_start_np[-1]))):
            d = self.st[c, ti.static(self.center)]
            l1 = ti.cast(0, self.dtype)
            for k in range(self.S):
                l1 += ti.abs(self.st[c, k])
            self.w[c] = self._weight(d, l1)

    def _prepare(self) -> None:
        t0 = time.perf_counter()
        if self.source is not None:
            cell, row = self.source
            self._k_cells_from(cell, row, row.shape[0])
        self._k_sort_rows()
        self._k_galerkin0()
        for l_ in range(self.m - 1):
            self._k_galerkin(l_)
        self._k_weights()
        far = int(self.far_pairs[None])
        if far:
            raise ValueError(f"{far} matrix entries couple rows more than one level-1 cell apart: the cells must "
                             "be at least as large as the neighbour search radius")
        self.last_setup_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------------ V-cycle
    @ti.kernel
    def _k_down0(self):
        """Level 0: two Jacobi sweeps from zero on A u = r into u0, then b_1 = P^T (r - A u0)."""
        n = self.n[None]
        two = ti.cast(2, self.dtype)
        for i in range(n):
            s = self.diag[i] * self.inv_diag[i] * self.r[i]
            for k in range(ti.min(self.count[i], self.max_nb)):
                j = self.cols[i, k]
                s += self.vals[i, k] * self.inv_diag[j] * self.r[j]
            self.u0[i] = self.inv_diag[i] * (two * self.r[i] - s)
        for c in range(ti.static(self.ncells[0])):
            s = ti.cast(0, self.dtype)
            for q in range(self.cstart[c], self.cstart[c + 1]):
                i = self.rlist[q]
                s += self.r[i] - self.row_times(i, self.u0)
            self.gb[c] = s

    @ti.kernel
    def _k_up0(self, first: ti.i32):
        """Level 0: y = u0 + alpha P t_1, two Jacobi sweeps from y into z; r.z, and beta = r.z / (last r.z)
        (0 when `first`)."""
        n = self.n[None]
        alpha = ti.cast(self.overcorrection, self.dtype)
        self.rz_new[None] = ti.cast(0, self.dtype)
        for i in range(n):
            ci = self.agg[i]
            yi = self.u0[i]
            if ci >= 0:
                yi += alpha * self.gt[ci]
            s = self.diag[i] * yi
            for k in range(ti.min(self.count[i], self.max_nb)):
                j = self.cols[i, k]
                yj = self.u0[j]
                cj = self.agg[j]
                if cj >= 0:
                    yj += alpha * self.gt[cj]
                s += self.vals[i, k] * yj
            self.t0[i] = yi + self.inv_diag[i] * (self.r[i] - s)
        if ti.static(self.reduction == "two_stage"):  # r.z in two stages, without atomics (ell_pcg.py)
            zero = ti.cast(0, self.dtype)
            for t in range(STAGE_THREADS):
                acc = zero
                i = t
                while i < n:
                    acc += self._second_sweep(i)
                    i += STAGE_THREADS
                self.stage[t] = ti.Vector([acc, zero, zero])
            self.rz_new[None] = self._folded()[0]
        else:
            for i in range(n):
                self.rz_new[None] += self._second_sweep(i)
        rz = self.rz[None]
        new = self.rz_new[None]
        beta = ti.cast(0, self.dtype)
        if first == 0 and rz > 0:
            beta = new / rz
        self.beta[None] = beta
        self.rz[None] = new

    @ti.func
    def _second_sweep(self, i):
        """Level 0's second Jacobi sweep at row i: z_i from t0; returns r_i z_i, row i's share of r.z."""
        zi = self.t0[i] + self.inv_diag[i] * (self.r[i] - self.row_times(i, self.t0))
        self.z[i] = zi
        return self.r[i] * zi

    @ti.func
    def _down(self, l):
        """Cell level l: two Jacobi sweeps from zero into t_l, then b_(l+1) = P^T (b_l - A_l t_l)."""
        two = ti.cast(2, self.dtype)
        base = self.lev_start[l]
        for c in range(self.lev_start[l + 1] - base):
            t = ti.cast(0, self.dtype)
            if self.w[base + c] != 0:
                t = self.w[base + c] * (two * self.gb[base + c] - self._g_awb(l, base, c, self._coords(l, c)))
            self.gt[base + c] = t
        cb = self.lev_start[l + 1]
        for C in range(self.lev_start[l + 2] - cb):
            CC = self._coords(l + 1, C)
            s = ti.cast(0, self.dtype)
            for ch in range(ti.static(2**self.dim)):
                fc = self._child(CC, ch)
                if self._in_level(l, fc) == 1:
                    f = self._lin(l, fc)
                    if self.w[base + f] != 0:
                        s += self.gb[base + f] - self._g_av(l, base, self.gt, f, fc)
            self.gb[cb + C] = s

    @ti.func
    def _up(self, l):
        """Cell level l: y = t_l + alpha P t_(l+1), two Jacobi sweeps from y, the result in t_l (the
        prolongation formed inside the first sweep)."""
        alpha = ti.cast(self.overcorrection, self.dtype)
        base = self.lev_start[l]
        cb = self.lev_start[l + 1]
        for c in range(cb - base):
            x = ti.cast(0, self.dtype)
            wc = self.w[base + c]
            if wc != 0:
                cc = self._coords(l, c)
                yc = self.gt[base + c] + alpha * self.gt[cb + self._lin(l + 1, cc // 2)]
                s = ti.cast(0, self.dtype)
                for k in range(self.S):
                    a = self.st[base + c, k]
                    if a != 0:
                        nc = self._ncoords(l, cc, k)
                        s += a * (self.gt[base + self._lin(l, nc)] + alpha * self.gt[cb + self._lin(l + 1, nc // 2)])
                x = yc + wc * (self.gb[base + c] - s)
            self.gx[base + c] = x
        self._sweep(l, base, self.gx, self.gt)

    @ti.func
    def _sweep(self, l, base, src: ti.template(), dst: ti.template()):
        for c in range(self.lev_start[l + 1] - base):
            y = ti.cast(0, self.dtype)
            if self.w[base + c] != 0:
                av = self._g_av(l, base, src, c, self._coords(l, c))
                y = src[base + c] + self.w[base + c] * (self.gb[base + c] - av)
            dst[base + c] = y

    @ti.kernel
    def _k_down(self, l: ti.i32):
        self._down(l)

    @ti.kernel
    def _k_up(self, l: ti.i32):
        self._up(l)

    @ti.kernel
    def _k_serial_levels(self, l0: ti.i32):
        """Levels l0 .. the coarsest in one serial task: down, COARSEST_SWEEPS sweeps, up."""
        m = ti.static(self.m)
        for _ in range(1):
            for l in range(l0, m - 1):
                self._down(l)
            lc = m - 1
            base = self.lev_start[lc]
            two = ti.cast(2, self.dtype)
            for c in range(self.lev_start[lc + 1] - base):
                self.gt[base + c] = self.w[base + c] * (two * self.gb[base + c]
                                                        - self._g_awb(lc, base, c, self._coords(lc, c)))
            for _k in range((COARSEST_SWEEPS - 2) // 2):
                self._sweep(lc, base, self.gt, self.gx)
                self._sweep(lc, base, self.gx, self.gt)
            for q in range(m - 1 - l0):
                self._up(m - 2 - q)

    def _vcycle(self, first: int) -> None:
        """z = B r (one V-cycle), with r.z and the next beta on the device."""
        self._k_down0()
        for l_ in range(self.n_par):
            self._k_down(l_)
        self._k_serial_levels(self.n_par)
        for l_ in reversed(range(self.n_par)):
            self._k_up(l_)
        self._k_up0(first)

    # ------------------------------------------------------------------ CG
    @ti.kernel
    def _k_residual_plain(self) -> ti.types.vector(2, ti.f64):
        """r = b - A x; returns (|b|^2, |r|^2)."""
        n = self.n[None]
        zero = ti.cast(0, self.dtype)
        self.bb[None] = zero
        self.rr[None] = zero
        for i in range(n):
            bi = self.b[i]
            ri = bi - self.row_times(i, self.x)
            self.r[i] = ri
            self.bb[None] += bi * bi
            self.rr[None] += ri * ri
        return ti.Vector([ti.cast(self.bb[None], ti.f64), ti.cast(self.rr[None], ti.f64)])

    def _restart(self):
        self._fresh = True
        if self.reduction == "two_stage":
            return tuple(float(v) for v in self._k_residual_two_stage(False))
        return tuple(float(v) for v in self._k_residual_plain())

    def _iterate(self) -> float:
        # the V-cycle at the start of an iteration, on the r it needs: none is spent after the last
        # iteration or on the final check of the true residual
        self._vcycle(1 if self._fresh else 0)
        self._fresh = False
        return float(self._k_iterate_step(False))

    # ------------------------------------------------------------------ host helpers (tests, tools)
    def apply(self, r) -> np.ndarray:
        """z = B r for the matrix and cells loaded (after `prepare`): the preconditioner as an operator."""
        np_fp = np.float64 if self.dtype == ti.f64 else np.float32
        n = int(self.n[None])
        a = np.zeros(self.n_max, dtype=np_fp)
        a[:n] = np.asarray(r)[:n]
        self.r.from_numpy(a)
        self._vcycle(1)
        return self.z.to_numpy()[:n].astype(np.float64)

    def prepare(self) -> None:
        """Build the hierarchy for the matrix now in the fields (`solve` does it itself)."""
        self.check_overflow()
        self._prepare()
