"""EllPCG (ELL matrix + Jacobi-preconditioned CG in Taichi kernels) against scipy on PPE-like matrices.

Accuracy bound used throughout: for any x, |x - x*| / |x*| <= cond_2(A) |b - A x| / |b| (A symmetric
positive definite, x* = A^-1 b), so a solve that stops at relative residual <= tol is within
cond(A) * tol of the exact solution. The residual is recomputed here in f64 with scipy, independently
of the solver's own figure.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spl
import taichi as ti
from scipy.spatial import cKDTree

from taichi_sph.linalg.ell_pcg import EllOverflowError, EllPCG
from taichi_sph.sph import kernels

TOL = 1.0e-8


def sph_lattice_ppe(shape, dx=0.01, jitter=0.1, seed=0, positions=False):
    """PPE matrix of a water patch at rest: jittered lattice, cubic-spline Laplacian pair weights
    K_ij = -2 dx^d r dW/dr / (r^2 + eta^2) (kernels.py, support 2.4 dx), Dirichlet rows for the top two
    layers (their columns moved to the right-hand side), no entries across the other sides (Neumann).
    Returns (A csr, b), and the particle positions with `positions`."""
    rng = np.random.default_rng(seed)
    dim = len(shape)
    grids = np.meshgrid(*[np.arange(s) for s in shape], indexing="ij")
    idx = np.stack([g.ravel() for g in grids], axis=1)
    x = (idx + rng.uniform(-jitter, jitter, idx.shape)) * dx
    n = len(x)
    dirichlet = idx[:, -1] >= shape[-1] - 2
    h = 0.5 * kernels.SUPPORT_FACTOR * dx
    i, j = cKDTree(x).query_pairs(kernels.SUPPORT_FACTOR * dx, output_type="ndarray").T
    r = np.linalg.norm(x[i] - x[j], axis=1)
    k = -2.0 * dx**dim * kernels.dw_dr_np(r, h, dim) * r / (r * r + 1.0e-4 * h * h)
    diag = np.zeros(n)
    np.add.at(diag, i, k)
    np.add.at(diag, j, k)
    diag[dirichlet] = np.median(diag[~dirichlet])
    keep = ~dirichlet[i] & ~dirichlet[j]
    rows = np.concatenate([i[keep], j[keep], np.arange(n)])
    cols = np.concatenate([j[keep], i[keep], np.arange(n)])
    vals = np.concatenate([-k[keep], -k[keep], diag])
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    b = np.where(dirichlet, 0.0, -(1.0 + 0.5 * rng.random(n)))
    return (A, b, x) if positions else (A, b)


def random_spd(n=600, degree=8, seed=1):
    """Weighted graph Laplacian of a random graph plus a small shift: sparse, SPD, cond ~ 1e3."""
    rng = np.random.default_rng(seed)
    i = np.repeat(np.arange(n), degree // 2)
    j = rng.integers(0, n, i.size)
    keep = i != j
    i, j = i[keep], j[keep]
    w = rng.uniform(0.1, 1.0, i.size)
    W = sp.coo_matrix((w, (i, j)), shape=(n, n))
    W = (W + W.T).tocsr()
    L = sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W
    A = (L + 1.0e-3 * sp.identity(n)).tocsr()
    return A, rng.standard_normal(n)


def max_offdiag(A) -> int:
    return int(np.max(np.diff(A.indptr))) - 1


@ti.kernel
def fill_rows(ell: ti.template(), indptr: ti.types.ndarray(), indices: ti.types.ndarray(),
              data: ti.types.ndarray(), b: ti.types.ndarray(), n: ti.i32):
    """Assembly the way a solver kernel does it: one thread per row, through start_row / add. The
    diagonal goes in two halves and the first off-diagonal entry of each row in two halves, to check
    that repeated entries are summed as by a SparseMatrixBuilder."""
    for i in range(n):
        ell.start_row(i)
        first = 1
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            if j == i:
                ell.add(i, i, 0.5 * data[k])
                ell.add(i, i, 0.5 * data[k])
            elif first == 1:
                ell.add(i, j, 0.25 * data[k])
                ell.add(i, j, 0.75 * data[k])
                first = 0
            else:
                ell.add(i, j, data[k])
        ell.b[i] = b[i]


@ti.kernel
def fill_too_many(ell: ti.template(), extra: ti.i32):
    ell.start_row(0)
    for k in range(ell.max_nb + extra):
        ell.add(0, 1, 1.0)


@pytest.fixture(scope="module")
def lattice(ti_cpu):
    A, b = sph_lattice_ppe((30, 30))
    return A, b, spl.spsolve(A.tocsc(), b), np.linalg.cond(A.toarray())


@pytest.fixture(scope="module")
def spd(ti_cpu):
    A, b = random_spd()
    return A, b, spl.spsolve(A.tocsc(), b), np.linalg.cond(A.toarray())


@pytest.fixture(scope="module")
def ell(lattice, spd):
    """One solver shared by the f64 tests (each instance compiles its own kernels); n_max is above
    both sizes, so some rows are always inactive."""
    mats = (lattice[0], spd[0])
    return EllPCG(max(A.shape[0] for A in mats) + 37, max(max_offdiag(A) for A in mats) + 1, TOL, 5000)


def rel_residual(A, x, b) -> float:
    return float(np.linalg.norm(b - A @ x) / np.linalg.norm(b))


def scipy_pcg_iterations(A, b, tol) -> int:
    count = [0]

    def cb(_xk):
        count[0] += 1

    _x, info = spl.cg(A, b, x0=np.zeros_like(b), rtol=tol, atol=0.0, maxiter=5000,
                      M=sp.diags(1.0 / A.diagonal()), callback=cb)
    assert info == 0
    return count[0]


def check_solution(A, b, x_exact, cond, x, iterations, residual, converged):
    n = A.shape[0]
    x = x[:n]
    true_res = rel_residual(A, x, b)
    assert converged
    assert true_res <= TOL
    # the reported residual is the true one of the returned x, not the CG recurrence: the two f64
    # evaluations of b - A x differ by round-off only (|A||x| eps / |b| ~ 1e-13 here vs 1e-8)
    assert residual == pytest.approx(true_res, rel=1e-3)
    err = np.linalg.norm(x - x_exact) / np.linalg.norm(x_exact)
    assert err <= cond * true_res
    assert iterations > 10  # a real solve, not a lucky start


def test_fill_in_kernel_matches_the_matrix(ell, lattice):
    A, b, x_exact, cond = lattice
    n = A.shape[0]
    fill_rows(ell, A.indptr.astype(np.int32), A.indices.astype(np.int32), A.data, b, n)
    ell.n[None] = n
    # summing the split entries rounds at most one ulp of each entry
    assert abs(ell.to_csr() - A).max() <= 1e-15 * abs(A).max()
    ell.x.fill(0.0)
    it, res, ok = ell.solve(n)
    check_solution(A, b, x_exact, cond, ell.x.to_numpy(), it, res, ok)


@pytest.mark.parametrize("case", ["lattice", "spd"])
def test_solution_and_iterations_match_scipy(case, request):
    A, b, x_exact, cond = request.getfixturevalue(case)
    n = A.shape[0]
    solver = request.getfixturevalue("ell")
    solver.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
    it, res, ok = solver.solve()
    check_solution(A, b, x_exact, cond, solver.x.to_numpy(), it, res, ok)
    # same algorithm, preconditioner, start and stopping rule as scipy's cg: the iterates agree up to
    # round-off, which can move the crossing of the tolerance by an iteration or two
    assert abs(it - scipy_pcg_iterations(A, b, TOL)) <= 3


def test_warm_start_from_the_solution(ell, lattice):
    A, b, x_exact, _ = lattice
    ell.load_csr(A.indptr, A.indices, A.data, b, x_exact)
    it, res, ok = ell.solve()
    assert ok and it <= 1
    assert res <= TOL


def test_iteration_limit_reports_not_converged(ell, lattice):
    A, b, _, _ = lattice
    n = A.shape[0]
    ell.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
    ell.max_iterations = 5
    try:
        it, res, ok = ell.solve()
    finally:
        ell.max_iterations = 5000
    assert (it, ok) == (5, False)
    # five iterations of a 900-unknown Laplacian leave the residual far above 1e-8
    assert res > 1e-3
    assert res == pytest.approx(rel_residual(A, ell.x.to_numpy()[:n], b), rel=1e-6)


def test_zero_rhs_gives_zero(ell, lattice):
    A = lattice[0]
    n = A.shape[0]
    ell.load_csr(A.indptr, A.indices, A.data, np.zeros(n), np.random.default_rng(3).standard_normal(n))
    assert ell.solve() == (0, 0.0, True)
    assert not ell.x.to_numpy()[:n].any()


def test_rows_beyond_n_are_ignored(ell, lattice):
    A, b, x_exact, cond = lattice
    n = A.shape[0]
    ell.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
    # garbage in the inactive rows: NaN values, full rows pointing at every column
    junk = np.full(ell.n_max - n, np.nan)
    for f in (ell.b, ell.diag, ell.x):
        a = f.to_numpy()
        a[n:] = junk
        f.from_numpy(a)
    count = ell.count.to_numpy()
    count[n:] = ell.max_nb
    ell.count.from_numpy(count)
    vals = ell.vals.to_numpy()
    vals[n:] = np.nan
    ell.vals.from_numpy(vals)
    it, res, ok = ell.solve(n)
    check_solution(A, b, x_exact, cond, ell.x.to_numpy(), it, res, ok)


def test_overflowing_row_is_refused(ell):
    fill_too_many(ell, 2)
    with pytest.raises(EllOverflowError, match=rf"has {ell.max_nb + 2} off-diagonal entries"):
        ell.solve()
    ell.check_overflow()  # reported once, then cleared


def test_column_layout_and_growing_the_width(lattice):
    """A row too long for the width is refused with the count it needs; the wider solver from
    `with_width` keeps the settings (here the GPU-style column layout) and solves."""
    A, b, x_exact, cond = lattice
    n = A.shape[0]
    args = (A.indptr.astype(np.int32), A.indices.astype(np.int32), A.data, b, n)
    narrow = EllPCG(n, max_offdiag(A) - 3, TOL, 5000, layout="column")
    fill_rows(narrow, *args)
    with pytest.raises(EllOverflowError) as err:
        narrow.solve(n)
    assert err.value.needed == max_offdiag(A) + 1  # fill_rows splits one entry per row in two
    wide = narrow.with_width(err.value.needed)
    assert wide.layout == "column" and wide.max_nb == err.value.needed
    fill_rows(wide, *args)
    wide.x.fill(0.0)
    it, res, ok = wide.solve(n)
    check_solution(A, b, x_exact, cond, wide.x.to_numpy(), it, res, ok)


def test_f32_reports_its_true_residual(lattice):
    A, b, x_exact, cond = lattice
    n = A.shape[0]
    solver = EllPCG(n, max_offdiag(A), 1e-9, 5000, dtype=ti.f32)
    solver.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
    _it, res, ok = solver.solve()
    x = solver.x.to_numpy().astype(np.float64)
    true_res = rel_residual(A, x, b)
    # f32 cannot reach 1e-9: the recurrence residual can, the true one stalls near eps_32 |A||x| / |b|
    assert not ok
    assert res > 1e-9 and true_res > 1e-9
    # the reported residual is b - A x evaluated in f32: equal to the f64 one within f32 round-off
    # of the same size as the residual itself, so within a factor 2
    assert 0.5 * true_res <= res <= 2.0 * true_res
    assert np.linalg.norm(x - x_exact) / np.linalg.norm(x_exact) <= cond * true_res


@pytest.mark.parametrize("case", ["lattice", "spd"])
def test_two_stage_reduction_gives_the_atomic_iterates(case, request):
    """The two-stage dot products (the CUDA choice, forced here on the CPU) are the same CG: the same
    solution to the tolerance and the same iteration count within the round-off that moves the crossing
    of the tolerance (the sums are taken in another order), as against scipy above."""
    A, b, x_exact, cond = request.getfixturevalue(case)
    n = A.shape[0]
    runs = {}
    for reduction in ("atomic", "two_stage"):
        solver = EllPCG(n, max_offdiag(A), TOL, 5000, reduction=reduction)
        assert solver.reduction == reduction
        solver.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
        it, res, ok = solver.solve()
        check_solution(A, b, x_exact, cond, solver.x.to_numpy(), it, res, ok)
        runs[reduction] = it
    assert abs(runs["atomic"] - runs["two_stage"]) <= 2, runs


def test_reduction_choice(ti_cpu):
    """auto is Taichi's atomic reduction on the CPU; a bad name is refused."""
    assert EllPCG(10, 4).reduction == "atomic"
    with pytest.raises(ValueError, match="reduction"):
        EllPCG(10, 4, reduction="tree")


@pytest.mark.parametrize("reduction", ["atomic", "two_stage"])
@pytest.mark.parametrize("case", ["lattice", "spd"])
def test_batched_iterations_give_the_same_solve(case, reduction, request):
    """Batches of iterations launched without reading anything back (`batch` > 1, the CUDA choice; forced
    here on the CPU), the convergence state kept on the device, give the solve of one launch and one
    read per iteration bit for bit: the same iterates, the same count and the same residual. Also when
    the iteration limit stops CG first (a limit that is not a multiple of the batch), and from a warm
    start that needs no iteration at all."""
    A, b, x_exact, cond = request.getfixturevalue(case)
    n = A.shape[0]
    for limit in (5000, 19):
        runs = {}
        for batch in (1, 8):
            solver = EllPCG(n, max_offdiag(A), TOL, limit, reduction=reduction, batch=batch)
            solver.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
            it, res, ok = solver.solve()
            runs[batch] = (it, res, ok, solver.x.to_numpy()[:n])
            if limit == 5000:
                check_solution(A, b, x_exact, cond, runs[batch][3], it, res, ok)
                again = solver.solve()  # warm: converged already, no iteration
                assert again[0] == 0 and again[2]
            else:
                assert it == limit and not ok
        assert runs[1][:3] == runs[8][:3], (runs[1][:3], runs[8][:3])
        assert np.array_equal(runs[1][3], runs[8][3])


def test_batch_choice(ti_cpu):
    """auto is one iteration per read on the CPU (launches are synchronous there); a bad batch is refused."""
    assert EllPCG(10, 4).batch == 1
    with pytest.raises(ValueError, match="batch"):
        EllPCG(10, 4, batch=0)
