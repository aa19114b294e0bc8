"""PPE solver in Taichi kernels: a matrix in ELL form and a Jacobi-preconditioned conjugate gradient.

The matrix of the pressure Poisson equation (SPEC 3 step 3, seed 000 eq 31 in the symmetric form of
eq 24) has one row per water particle and off-diagonal entries only between a particle and its listed
neighbours, so a row holds at most `max_nb` off-diagonal entries. It is stored row by row in fields
sized (n_max, max_nb): `cols[i, k]`, `vals[i, k]` for k < `count[i]`, the diagonal apart in `diag[i]`,
the right-hand side in `b[i]` and the solution in `x[i]`. Only the first `n` rows are active (`n` is a
0-d field, so the active count can change every step without recompiling); columns must be < n.

An assembly kernel fills a row from the loop iteration that owns it (one thread per row, no atomics),
with the same `+=` meaning as a SparseMatrixBuilder (`add(i, i, v)` adds to the diagonal, a repeated
column is summed). The isph assembly would change only where it now calls the builder:

    @ti.kernel
    def _k_assemble(self, ell: ti.template()):
        for i in range(self.n):
            if self.kind[i] == WATER:
                ri = self.row[i]
                ell.start_row(ri)                          # count = 0, diagonal = 0
                if self.solve_mask[i] == 1 and self.free[i] == 0:
                    for k in range(self.grid.nbr_count[i]):
                        ...
                        diag += K
                        if self.free[j] == 1 or self.solve_mask[j] == 0:
                            rhs += K * self._dirichlet_value(j)
                        else:
                            ell.add(ri, self.row[j], -K)   # was  A[ri, self.row[j]] += -K
                    ell.add(ri, ri, diag)                  # was  A[ri, ri] += diag
                    ell.b[ri] = rhs - source               # was  self.b[ri] = ...
                else:
                    ell.add(ri, ri, dirichlet_diag)
                    ell.b[ri] = dirichlet_diag * self._dirichlet_value(i)

    ppe = EllPCG(n_max=n_water, max_nb=width, tolerance=1e-8, max_iterations=2000)
    self._k_assemble(ppe)                  # ppe.x still holds the last pressure: warm start
    iterations, residual, converged = ppe.solve(n=n_water)

A row that needs more than `max_nb` off-diagonal slots is not written past its end: the largest
count needed is recorded and `solve` raises EllOverflowError before solving a truncated matrix
(`with_width` then gives a wider solver to refill). Rows are strided by `max_nb` in memory, so the
width costs memory traffic even where rows are short: size it near the largest row expected (the
lattice neighbour count with a margin) rather than at the neighbour-list capacity; tools/bench_ppe.py
measures both.

Solver: preconditioned CG (Hestenes-Stiefel) with M = diag(A), starting from the x already in the
field. Each iteration is one kernel launch (p update, matvec with the p.Ap reduction, x/r/z update
with the r.r and r.z reductions) that returns one scalar, |r|^2, to the host; no vector leaves the
device. A small system on the CPU (SERIAL_ROWS) runs all its iterations in one launch on the calling
thread, which stops where the host loop would: launching costs more than such an iteration's work. Its
dot products round differently from the loops launched one by one (x within ~5e-13 of |x| on a 900-row
PPE, the same iteration count, tests/test_determinism.py), and it is deterministic. When the recurrence
says |r| / |b| <= tolerance, the true residual b - A x is computed; if it is above the tolerance
(round-off drift, f32), CG restarts from the true residual, at most MAX_RESTARTS times, within
`max_iterations` iterations in all. A zero right-hand side gives x = 0.
A matrix whose null space is the constants (a PPE without any Dirichlet row: a closed or periodic box
full of water) is solved with `zero_mean=True`: b is projected onto the range of A (its mean
removed), CG converges in that range, and the zero-mean solution is returned.
Batched iterations on CUDA (`batch="auto"`: BATCH_GPU): Jacobi-PCG launches its iterations in batches
without reading anything back, and reads a gate kept on the device once per batch. An iteration runs
only while the gate is open and closes it where the host loop would have stopped (breakdown, non-finite,
converged, the iteration limit), so a batch gives the same iterates, count and residual as one read per
iteration (tests/test_ell_pcg.py, bit for bit on the CPU) without the host waiting on every launch.
Measured on an H100 with one read per iteration: 0.27-0.34 ms an iteration at 10k to 1M rows, of which
the bytes need 0.1-0.15 ms at 1M (docs/performance.md, "GPU"); the batches are not yet timed there.
Dot products on CUDA (`reduction="auto"`): Taichi 1.7.4 reduces a sum into one scalar by giving
each GPU thread its partial sum and then adding the partials with one atomic per thread into that
scalar; its CUDA runtime combines a warp's partials first only for f32 and i32. In f64 every launched
thread (about half a million on an H100) adds into the same address, serialised: 5.1 ms per CG
iteration whatever the matrix size (1M or 4M rows, docs/performance.md, "GPU"). The "two_stage"
reduction has STAGE_THREADS threads each sum rows t, t + STAGE_THREADS, ... (neighbouring threads take
neighbouring rows, so the loads stay coalesced) into its own slot, then FOLD_THREADS threads fold those
slots, then one thread adds the FOLD_THREADS folds in order: no atomics, and the same sum on every run.
"atomic" keeps Taichi's reduction (the CPU's choice: there the partials are per CPU thread). Measured
on an H100 (docs/performance.md, "GPU"), two stages took the f64 iteration from 4.97 to 0.29 ms at 1M
rows in 2D (75 % of the copy kernel's bandwidth at 4M rows, 64 % at 1M rows in 3D), and were faster in
f32 too, where Taichi's warp sums leave one atomic per warp (0.27 against 0.35 ms at 1M rows in 2D, 0.54
against 0.56 at 4M, 0.36 against 0.42 at 1M in 3D): "auto" takes them on CUDA at either precision.
The vectors use the runtime's default float (f32 or f64) unless `dtype` is given. An f32 solve stalls
where the rounding of b - A x, about eps_32 |A| |x| / |b|, meets the tolerance (1e-5 to 1e-4 relative
on a 900-row PPE) and then reports converged = False.
"""

import math

import numpy as np
import taichi as ti

#: true-residual restarts allowed after the recurrence residual has met the tolerance
MAX_RESTARTS = 3
#: Jacobi-PCG iterations launched per read of the convergence state on CUDA (`batch="auto"`)
BATCH_GPU = 8
#: on the CPU, a system of at most this many rows runs its Jacobi-PCG iterations serially on the calling
#: thread, all of them in one launch (`_k_iterate_serial`). Each parallel loop hands its work to Taichi's
#: thread pool and waits for it, which costs more than the loop's own work for a small system: the
#: permeameter at dx 5 mm (1,500 rows, 200 iterations a step) took 55 ms a step on 2 cores and 61 ms on one
#: thread, 22 / 19 ms with serial loops; at 6,000 rows 63 against 30 ms, at ~24,000 rows 176 against 120 ms
#: (2-core AMD EPYC). A launch per iteration then still cost about as much as its work: one launch for the
#: whole solve took the same step from 12-14 to 6-8 ms (docs/performance.md). The bound leaves larger
#: systems to the threads on machines with more cores, where their share of the work is smaller.
SERIAL_ROWS = 8192
#: two-stage dot products: threads of the first stage (each sums every STAGE_THREADS-th row), and of the fold
STAGE_THREADS = 1 << 16
FOLD_THREADS = 256


class EllOverflowError(RuntimeError):
    """A PPE row has more off-diagonal entries than the ELL storage holds."""

    def __init__(self, needed: int, capacity: int):
        self.needed = int(needed)
        self.capacity = int(capacity)
        super().__init__(
            f"a PPE row has {self.needed} off-diagonal entries but the ELL matrix holds {self.capacity} per row; "
            f"raise the config key `neighbours.max` to at least {self.needed}"
        )


def _default_fp():
    from taichi.lang import impl

    return impl.get_runtime().default_fp


@ti.data_oriented
class EllPCG:
    """Symmetric positive definite solve A x = b, A in ELL form in Taichi fields, Jacobi-PCG.

    layout: "row" stores the slots of one row contiguously (a CPU thread per row reads them in one
    stream; measured fastest on CPU), "column" stores slot k of consecutive rows contiguously (the
    usual GPU ELL layout, for coalesced loads; on an H100 the faster in f64 and about even in f32,
    docs/performance.md "GPU"); "auto" picks "column" on CUDA and "row" elsewhere.

    batch: Jacobi-PCG iterations launched per read of the convergence state (module docstring); "auto":
    BATCH_GPU on CUDA, 1 elsewhere (the CPU's launches are synchronous: nothing to gain), and on the CPU a
    system of at most SERIAL_ROWS rows runs all its iterations in one launch; a number is taken as given
    (1: one launch and one read per iteration, as tests/test_ell_pcg.py compares the batches with). A
    subclass with its own preconditioner (mg_pcg.py) iterates one launch per read.

    reduction: how an iteration's dot products are summed: "atomic" (Taichi's own reduction), "two_stage"
    (partial sums in slots, folded without atomics; see the module's docstring), or "auto": "two_stage"
    on CUDA (f32 and f64), "atomic" elsewhere.
    """

    name = "ell_pcg"

    def __init__(self, n_max: int, max_nb: int, tolerance: float = 1.0e-8, max_iterations: int = 2000,
                 dtype=None, layout: str = "auto", reduction: str = "auto", batch: int | str = "auto"):
        if n_max < 1 or max_nb < 1:
            raise ValueError(f"EllPCG needs n_max >= 1 and max_nb >= 1, not {n_max} and {max_nb}")
        self.n_max = int(n_max)
        self.max_nb = int(max_nb)
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.dtype = fp = dtype if dtype is not None else _default_fp()
        from taichi.lang import impl

        arch = impl.current_cfg().arch
        if layout == "auto":
            layout = "column" if arch == ti.cuda else "row"
        if layout not in ("row", "column"):
            raise ValueError(f"layout must be 'row', 'column' or 'auto', not {layout!r}")
        self.layout = layout
        if reduction == "auto":
            reduction = "two_stage" if arch == ti.cuda else "atomic"
        if reduction not in ("atomic", "two_stage"):
            raise ValueError(f"reduction must be 'atomic', 'two_stage' or 'auto', not {reduction!r}")
        self.reduction = reduction
        self._cpu = arch == ti.cpu
        #: this solve's systems are small enough for serial loops (SERIAL_ROWS; set by `solve`)
        self._serial = False
        #: the batch as given: with "auto" a small system on the CPU runs its iterations in one launch
        #: (`_k_iterate_serial`); a batch given as a number is taken as it is
        self.batch_setting = batch
        if batch == "auto":
            batch = BATCH_GPU if arch == ti.cuda else 1
        if not isinstance(batch, int) or batch < 1:
            raise ValueError(f"batch must be a positive integer or 'auto', not {batch!r}")
        self.batch = batch
        if reduction == "two_stage":
            self.stage = ti.Vector.field(3, fp, STAGE_THREADS)
            self.fold = ti.Vector.field(3, fp, FOLD_THREADS)
        self.cols = ti.field(ti.i32)
        self.vals = ti.field(fp)
        for f in (self.cols, self.vals):
            if layout == "row":
                ti.root.dense(ti.i, self.n_max).dense(ti.j, self.max_nb).place(f)
            else:
                ti.root.dense(ti.j, self.max_nb).dense(ti.i, self.n_max).place(f)
        self.count = ti.field(ti.i32, self.n_max)
        self.diag = ti.field(fp, self.n_max)
        self.b = ti.field(fp, self.n_max)
        self.x = ti.field(fp, self.n_max)
        self.inv_diag = ti.field(fp, self.n_max)
        self.r = ti.field(fp, self.n_max)
        self.z = ti.field(fp, self.n_max)
        self.p = ti.field(fp, self.n_max)
        self.ap = ti.field(fp, self.n_max)
        self.n = ti.field(ti.i32, ())
        self.overflow = ti.field(ti.i32, ())
        # CG scalars stay on the device between kernels
        self.bb = ti.field(fp, ())
        self.rr = ti.field(fp, ())
        self.rz = ti.field(fp, ())
        self.rz_new = ti.field(fp, ())
        self.pap = ti.field(fp, ())
        self.alpha = ti.field(fp, ())
        self.beta = ti.field(fp, ())
        self.breakdown = ti.field(ti.i32, ())
        # batched iterations (`batch` > 1): stopped, iterations made and the last |r|^2, kept on the device
        self.gate = ti.Vector.field(3, ti.f64, ())
        self.mean = ti.field(ti.f64, ())
        self.n[None] = self.n_max

    # ------------------------------------------------------------------ filling rows in a kernel
    @ti.func
    def start_row(self, i):
        """Empty row i (no off-diagonal entries, zero diagonal); call before `add` on that row."""
        self.count[i] = 0
        self.diag[i] = ti.cast(0, self.dtype)

    @ti.func
    def add(self, i, j, v):
        """A[i, j] += v (v cast to the solver's float). Only the thread that owns row i may call it."""
        vc = ti.cast(v, self.dtype)
        if j == i:
            self.diag[i] += vc
        else:
            k = self.count[i]
            if k < self.max_nb:
                self.cols[i, k] = j
                self.vals[i, k] = vc
            else:
                ti.atomic_max(self.overflow[None], k + 1)
            self.count[i] = k + 1

    @ti.func
    def row_times(self, i, v: ti.template()):
        """(A v)_i."""
        s = self.diag[i] * v[i]
        for k in range(ti.min(self.count[i], self.max_nb)):
            s += self.vals[i, k] * v[self.cols[i, k]]
        return s

    def with_width(self, max_nb: int) -> "EllPCG":
        """A new solver with `max_nb` slots per row and the same settings, its x copied from this one
        (warm start); the matrix must be filled again. Its kernels compile anew (once)."""
        other = EllPCG(self.n_max, max_nb, self.tolerance, self.max_iterations, self.dtype, self.layout,
                       self.reduction, self.batch_setting)
        other.x.copy_from(self.x)
        other.n[None] = self.n[None]
        return other

    # ------------------------------------------------------------------ filling from the host
    def load_csr(self, indptr, indices, data, b=None, x0=None) -> None:
        """Fill the first n = len(indptr) - 1 rows from CSR arrays (e.g. a scipy.sparse matrix);
        optionally b and x0. Host-side convenience for tests and tools; solvers fill in kernels."""
        indptr = np.asarray(indptr, dtype=np.int64)
        indices = np.asarray(indices, dtype=np.int64)
        data = np.asarray(data, dtype=np.float64)
        n = len(indptr) - 1
        if n > self.n_max:
            raise ValueError(f"matrix has {n} rows but the ELL matrix holds {self.n_max}")
        rows = np.repeat(np.arange(n), np.diff(indptr))
        on_diag = rows == indices
        diag = np.zeros(self.n_max)
        np.add.at(diag, rows[on_diag], data[on_diag])
        r_off, c_off, v_off = rows[~on_diag], indices[~on_diag], data[~on_diag]
        count = np.bincount(r_off, minlength=self.n_max).astype(np.int32)
        if count.size and count.max() > self.max_nb:
            raise EllOverflowError(int(count.max()), self.max_nb)
        start = np.zeros(self.n_max + 1, dtype=np.int64)
        np.cumsum(count, out=start[1:])
        slot = np.arange(len(r_off)) - start[r_off]
        cols = np.zeros((self.n_max, self.max_nb), dtype=np.int32)
        vals = np.zeros((self.n_max, self.max_nb))
        cols[r_off, slot] = c_off
        vals[r_off, slot] = v_off
        np_fp = np.float64 if self.dtype == ti.f64 else np.float32
        self.cols.from_numpy(cols)
        self.vals.from_numpy(vals.astype(np_fp))
        self.count.from_numpy(count)
        self.diag.from_numpy(diag.astype(np_fp))
        if b is not None:
            self.b.from_numpy(_padded(b, self.n_max, np_fp))
        if x0 is not None:
            self.x.from_numpy(_padded(x0, self.n_max, np_fp))
        self.n[None] = n

    def to_csr(self, n: int | None = None):
        """The first n rows as a scipy.sparse.csr_matrix (host-side, for checks)."""
        import scipy.sparse as sp

        n = int(self.n[None]) if n is None else int(n)
        count = np.minimum(self.count.to_numpy()[:n], self.max_nb)
        mask = np.arange(self.max_nb)[None, :] < count[:, None]
        rows = np.repeat(np.arange(n), count)
        cols = self.cols.to_numpy()[:n][mask]
        vals = self.vals.to_numpy()[:n][mask]
        idx = np.arange(n)
        all_rows = np.concatenate([rows, idx])
        all_cols = np.concatenate([cols, idx])
        all_vals = np.concatenate([vals, self.diag.to_numpy()[:n]]).astype(np.float64)
        return sp.csr_matrix((all_vals, (all_rows, all_cols)), shape=(n, n))

    # ------------------------------------------------------------------ CG kernels
    @ti.kernel
    def _k_residual(self, serial: ti.template()) -> ti.types.vector(2, ti.f64):
        """r = b - A x, z = M^-1 r, beta = 0 (p = z next); returns (|b|^2, |r|^2). With `serial` the loop
        runs on the calling thread (SERIAL_ROWS)."""
        n = self.n[None]
        zero = ti.cast(0, self.dtype)
        one = ti.cast(1, self.dtype)
        self.bb[None] = zero
        self.rr[None] = zero
        self.rz[None] = zero
        ti.loop_config(serialize=serial)
        for i in range(n):
            d = self.diag[i]
            inv = one
            if d > 0:
                inv = one / d
            self.inv_diag[i] = inv
            bi = self.b[i]
            ri = bi - self.row_times(i, self.x)
            zi = inv * ri
            self.r[i] = ri
            self.z[i] = zi
            self.bb[None] += bi * bi
            self.rr[None] += ri * ri
            self.rz[None] += ri * zi
        self.beta[None] = zero
        return ti.Vector([ti.cast(self.bb[None], ti.f64), ti.cast(self.rr[None], ti.f64)])

    @ti.kernel
    def _k_residual_two_stage(self, jacobi: ti.template()) -> ti.types.vector(2, ti.f64):
        """r = b - A x, and with `jacobi` z = M^-1 r and beta = 0 (`_k_residual`), its sums |b|^2, |r|^2
        and r.z in two stages (reduction "two_stage"); returns (|b|^2, |r|^2)."""
        n = self.n[None]
        zero = ti.cast(0, self.dtype)
        one = ti.cast(1, self.dtype)
        for t in range(STAGE_THREADS):
            s = ti.Vector([zero, zero, zero])
            i = t
            while i < n:
                bi = self.b[i]
                ri = bi - self.row_times(i, self.x)
                self.r[i] = ri
                s[0] += bi * bi
                s[1] += ri * ri
                if ti.static(jacobi):
                    d = self.diag[i]
                    inv = one
                    if d > 0:
                        inv = one / d
                    self.inv_diag[i] = inv
                    zi = inv * ri
                    self.z[i] = zi
                    s[2] += ri * zi
                i += STAGE_THREADS
            self.stage[t] = s
        sums = self._folded()
        self.bb[None] = sums[0]
        self.rr[None] = sums[1]
        if ti.static(jacobi):
            self.rz[None] = sums[2]
            self.beta[None] = zero
        return ti.Vector([ti.cast(sums[0], ti.f64), ti.cast(sums[1], ti.f64)])

    @ti.kernel
    def _k_iterate(self, jacobi: ti.template(), serial: ti.template()) -> ti.f64:
        """One PCG iteration: p = z + beta p, alpha = r.z / p.Ap, x += alpha p, r -= alpha Ap; with `jacobi`
        also z = D^-1 r, r.z and the next beta (a preconditioner of its own, as the multigrid V-cycle of
        mg_pcg.py, computes them itself). Returns the recurrence |r|^2, or -1 on breakdown (p.Ap <= 0).
        With `serial` its loops run on the calling thread (SERIAL_ROWS)."""
        return self._iteration(jacobi, 1, serial)

    @ti.func
    def _iteration(self, jacobi: ti.template(), live, serial: ti.template()):
        """`_k_iterate`'s body with Taichi's reductions; with live = 0 its loops are empty and it changes
        nothing (a batched iteration after the stop); with `serial` its loops are not parallel."""
        n = self.n[None] * live
        zero = ti.cast(0, self.dtype)
        beta = self.beta[None]
        ti.loop_config(serialize=serial)
        for i in range(n):
            self.p[i] = self.z[i] + beta * self.p[i]
        self.pap[None] = zero
        ti.loop_config(serialize=serial)
        for i in range(n):
            self.pap[None] += self._ap_row(i)
        alpha = zero
        if live == 1:
            alpha = self._step_length()
        self.rr[None] = zero
        if ti.static(jacobi):
            self.rz_new[None] = zero
        ti.loop_config(serialize=serial)
        for i in range(n):
            sums = self._update_row(i, alpha, jacobi)
            self.rr[None] += sums[0]
            if ti.static(jacobi):
                self.rz_new[None] += sums[1]
        out = ti.cast(-1.0, ti.f64)
        if live == 1:
            out = self._finish(jacobi)
        return out

    @ti.func
    def _ap_row(self, i):
        """(A p)_i into ap; returns p_i (A p)_i, row i's share of p.Ap."""
        api = self.row_times(i, self.p)
        self.ap[i] = api
        return self.p[i] * api

    @ti.func
    def _step_length(self):
        """alpha = r.z / p.Ap from the fields (0, with breakdown set, where p.Ap <= 0); returns alpha."""
        self.breakdown[None] = 0
        self.alpha[None] = ti.cast(0, self.dtype)
        if self.pap[None] > 0:
            self.alpha[None] = self.rz[None] / self.pap[None]
        else:
            self.breakdown[None] = 1
        return self.alpha[None]

    @ti.func
    def _update_row(self, i, alpha, jacobi: ti.template()):
        """x_i += alpha p_i, r_i -= alpha (A p)_i, and with `jacobi` z_i = r_i / d_i; returns (r_i^2, r_i z_i)."""
        self.x[i] += alpha * self.p[i]
        ri = self.r[i] - alpha * self.ap[i]
        self.r[i] = ri
        rz = ti.cast(0, self.dtype)
        if ti.static(jacobi):
            zi = self.inv_diag[i] * ri
            self.z[i] = zi
            rz = ri * zi
        return ti.Vector([ri * ri, rz])

    @ti.func
    def _finish(self, jacobi: ti.template()):
        """With `jacobi` the next beta = r.z(new) / r.z; returns the recurrence |r|^2, or -1 on breakdown."""
        if ti.static(jacobi):
            self.beta[None] = ti.cast(0, self.dtype)
            if self.rz[None] > 0:
                self.beta[None] = self.rz_new[None] / self.rz[None]
            self.rz[None] = self.rz_new[None]
        out = ti.cast(self.rr[None], ti.f64)
        if self.breakdown[None] == 1:
            out = -1.0
        return out

    @ti.func
    def _folded(self):
        """The sum of the first stage's slots (three components), folded by FOLD_THREADS threads and then
        added in order by one: no atomics, the same result on every run."""
        zero = ti.cast(0, self.dtype)
        for u in range(FOLD_THREADS):
            s = ti.Vector([zero, zero, zero])
            t = u
            while t < STAGE_THREADS:
                s += self.stage[t]
                t += FOLD_THREADS
            self.fold[u] = s
        total = ti.Vector([zero, zero, zero])
        ti.loop_config(serialize=True)
        for u in range(FOLD_THREADS):
            total += self.fold[u]
        return total

    @ti.kernel
    def _k_iterate_two_stage(self, jacobi: ti.template()) -> ti.f64:
        """`_k_iterate` with its dot products summed in two stages (reduction "two_stage")."""
        return self._iteration_two_stage(jacobi, 1)

    @ti.func
    def _iteration_two_stage(self, jacobi: ti.template(), live):
        """`_iteration` with its dot products summed in two stages."""
        n = self.n[None] * live
        threads = STAGE_THREADS * live
        zero = ti.cast(0, self.dtype)
        beta = self.beta[None]
        for i in range(n):
            self.p[i] = self.z[i] + beta * self.p[i]
        for t in range(threads):
            s = zero
            i = t
            while i < n:
                s += self._ap_row(i)
                i += STAGE_THREADS
            self.stage[t] = ti.Vector([s, zero, zero])
        folded = self._folded()  # at the kernel's top level, so that its loops run in parallel
        alpha = zero
        if live == 1:
            self.pap[None] = folded[0]
            alpha = self._step_length()
        for t in range(threads):
            s = ti.Vector([zero, zero, zero])
            i = t
            while i < n:
                sums = self._update_row(i, alpha, jacobi)
                s[0] += sums[0]
                s[1] += sums[1]
                i += STAGE_THREADS
            self.stage[t] = s
        sums = self._folded()
        out = ti.cast(-1.0, ti.f64)
        if live == 1:
            self.rr[None] = sums[0]
            if ti.static(jacobi):
                self.rz_new[None] = sums[1]
            out = self._finish(jacobi)
        return out

    @ti.kernel
    def _k_iterate_gated(self, jacobi: ti.template(), threshold: ti.f64, limit: ti.i32, serial: ti.template()):
        """One iteration of a batch (`batch` > 1), launched without reading anything back: it runs while the
        gate is open (no stop yet, fewer than `limit` iterations made in this batch series) and closes the
        gate where the host loop of `solve` would stop (breakdown, a non-finite |r|^2, or |r|^2 <=
        threshold). So a batch gives the iterates, the count and |r|^2 of one launch per iteration."""
        live = 0
        if self.gate[None][0] == 0.0 and self.gate[None][1] < limit:
            live = 1
        out = ti.cast(-1.0, ti.f64)
        if ti.static(self.reduction == "two_stage"):
            out = self._iteration_two_stage(jacobi, live)
        else:
            out = self._iteration(jacobi, live, serial)
        if live == 1:
            g = self.gate[None]
            g[1] += 1.0
            g[2] = out
            if not (out >= 0.0 and out > threshold):  # breakdown, non-finite or converged
                g[0] = 1.0
            self.gate[None] = g

    @ti.kernel
    def _k_iterate_serial(self, threshold: ti.f64, limit: ti.i32) -> ti.types.vector(2, ti.f64):
        """Jacobi-PCG iterations in one launch on the calling thread (a small system on the CPU,
        SERIAL_ROWS), until the recurrence stops where the host loop of `solve` would (breakdown, a
        non-finite |r|^2, or |r|^2 <= threshold) or `limit` iterations; returns (iterations, last |r|^2).
        The iterations of one launch each, without a launch's cost per iteration; their dot products round
        differently (the module's docstring)."""
        made = 0
        out = ti.cast(0.0, ti.f64)
        while made < limit:
            out = self._iteration(True, 1, True)
            made += 1
            if not (out >= 0.0 and out > threshold):
                break
        return ti.Vector([ti.cast(made, ti.f64), out])

    @ti.kernel
    def _k_gate_open(self):
        self.gate[None] = ti.Vector([0.0, 0.0, 0.0])

    @ti.kernel
    def _k_gate(self) -> ti.types.vector(3, ti.f64):
        return self.gate[None]

    @ti.kernel
    def _k_remove_mean(self, v: ti.template()):
        """v -= mean(v) over the first n rows (summed in f64)."""
        n = self.n[None]
        self.mean[None] = 0.0
        for i in range(n):
            self.mean[None] += ti.cast(v[i], ti.f64)
        m = ti.cast(self.mean[None] / ti.max(n, 1), self.dtype)
        for i in range(n):
            v[i] -= m

    @ti.kernel
    def _k_zero_x(self):
        for i in range(self.n[None]):
            self.x[i] = ti.cast(0, self.dtype)

    @ti.kernel
    def _k_take_overflow(self) -> ti.i32:
        out = self.overflow[None]
        self.overflow[None] = 0
        return out

    # ------------------------------------------------------------------ preconditioner hooks
    def _prepare(self) -> None:
        """Once per solve, after the matrix is filled: set up the preconditioner (Jacobi: nothing here,
        the inverse diagonal is taken in `_k_residual`)."""

    def _restart(self):
        """r = b - A x, z = M^-1 r, next direction p = z; returns (|b|^2, |r|^2)."""
        if self.reduction == "two_stage":
            return self._k_residual_two_stage(True)
        return self._k_residual(self._serial)

    def _iterate(self) -> float:
        """One PCG iteration; returns the recurrence |r|^2, or -1 on breakdown."""
        return self._k_iterate_step(True)

    def _iterate_batched(self, threshold: float, limit: int) -> int:
        """Jacobi-PCG iterations in batches of `batch` launches with one read of the gate after each batch,
        until the gate closes (the stops of `solve`'s loop) or `limit` iterations; returns their count."""
        self._k_gate_open()
        while True:
            for _ in range(min(self.batch, limit)):
                self._k_iterate_gated(True, threshold, limit, self._serial)
            stopped, made, _ = self._k_gate()
            if stopped or made >= limit:
                return int(made)

    def _k_iterate_step(self, jacobi: bool) -> float:
        """`_k_iterate` or its two-stage form, as `reduction` says."""
        if self.reduction == "two_stage":
            return self._k_iterate_two_stage(jacobi)
        return self._k_iterate(jacobi, self._serial)

    # ------------------------------------------------------------------ host API
    def check_overflow(self) -> None:
        """Raise EllOverflowError if a row was filled past `max_nb` since the last check."""
        needed = int(self._k_take_overflow())
        if needed > 0:
            raise EllOverflowError(needed, self.max_nb)

    def solve(self, n: int | None = None, zero_mean: bool = False):
        """Solve the first n rows (default: the n already set) from the x in the field; `zero_mean` for a
        singular A with the constants as null space (b's mean is removed, x returned with zero mean).

        Returns (iterations, relative residual |b - A x| / |b| of the returned x, converged).
        """
        self.check_overflow()
        if n is not None:
            if not 0 <= n <= self.n_max:
                raise ValueError(f"n = {n} is outside 0..{self.n_max}")
            self.n[None] = int(n)
        self._serial = self._cpu and int(self.n[None]) <= SERIAL_ROWS
        if zero_mean:
            self._k_remove_mean(self.b)
        self._prepare()
        bb, rr = (float(v) for v in self._restart())
        if not bb > 0.0:
            if math.isfinite(bb):
                self._k_zero_x()
                return 0, 0.0, True
            return 0, math.nan, False
        threshold = self.tolerance**2 * bb
        iterations = 0
        restarts = 0
        jacobi = type(self)._iterate is EllPCG._iterate  # not a subclass with its own preconditioner
        looped = jacobi and self._serial and self.reduction == "atomic" and self.batch_setting == "auto"
        batched = jacobi and self.batch > 1
        while math.isfinite(rr) and rr > threshold and iterations < self.max_iterations:
            if looped:
                iterations += int(self._k_iterate_serial(threshold, self.max_iterations - iterations)[0])
            elif batched:
                iterations += self._iterate_batched(threshold, self.max_iterations - iterations)
            while not (looped or batched) and iterations < self.max_iterations:
                rr_rec = self._iterate()
                iterations += 1
                if not rr_rec >= 0.0 or rr_rec <= threshold:  # breakdown, non-finite or converged
                    break
            bb, rr = (float(v) for v in self._restart())
            if rr <= threshold or restarts == MAX_RESTARTS:
                break
            restarts += 1
        residual = math.sqrt(rr / bb) if math.isfinite(rr) else math.nan
        if zero_mean:
            self._k_remove_mean(self.x)
        return iterations, residual, bool(residual <= self.tolerance)


def _padded(v, n: int, dtype) -> np.ndarray:
    out = np.zeros(n, dtype=dtype)
    v = np.asarray(v)
    out[: len(v)] = v
    return out
