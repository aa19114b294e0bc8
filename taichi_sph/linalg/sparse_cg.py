"""PPE solver on Taichi's sparse matrix: SparseMatrixBuilder assembly + SparseCG.

Facts this wrapper works around (Taichi 1.7.4):
- the builder has no bounds check on `max_num_triplets`: the caller sizes it as
  rows * (max neighbours + 1) and counts the triplets it adds itself (`check_triplets`);
- SparseCG's `atol` is a relative tolerance on CPU, it defaults to 50 iterations, and it prints the
  iteration count to stdout instead of returning it: the count is read from that output, and the
  true relative residual |b - A x| / |b| is computed here, so a solve that did not converge is
  always reported;
- on CUDA the matrix is f32 only and SparseCG has no preconditioner.
"""

from __future__ import annotations

import os
import re
import sys
import tempfile

import numpy as np
import taichi as ti


class _CaptureFd1:
    """Capture what native code writes to file descriptor 1."""

    def __enter__(self):
        sys.stdout.flush()
        self._tmp = tempfile.TemporaryFile(mode="w+b")
        self._saved = os.dup(1)
        os.dup2(self._tmp.fileno(), 1)
        return self

    def __exit__(self, *exc):
        try:
            sys.stdout.flush()
        except Exception:  # noqa: BLE001
            pass
        os.dup2(self._saved, 1)
        os.close(self._saved)
        self._tmp.seek(0)
        self.text = self._tmp.read().decode(errors="replace")
        self._tmp.close()
        return False


_ITER = re.compile(r"#iterations:\s*(\d+)")


class SparseCGSolver:
    """Symmetric positive definite solve A x = b with A assembled through a SparseMatrixBuilder."""

    name = "sparse_cg"

    def __init__(self, n: int, max_triplets: int, dtype, tolerance: float, max_iterations: int):
        self.n = int(n)
        self.max_triplets = int(max_triplets)
        self.dtype = dtype
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.builder = ti.linalg.SparseMatrixBuilder(self.n, self.n, max_num_triplets=self.max_triplets, dtype=dtype)
        self.matrix = None

    def check_triplets(self, count: int) -> None:
        if count > self.max_triplets:
            raise RuntimeError(f"PPE assembly needs {count} triplets but the builder holds {self.max_triplets}")

    def build(self):
        self.matrix = self.builder.build()
        return self.matrix

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None, zero_mean: bool = False):
        """Returns (x, iterations, relative residual, converged).

        zero_mean: A is singular with the constants as null space (a PPE without a Dirichlet row, whose
        rows sum to zero): b is projected onto the range of A (its mean removed) and the solution
        returned is the one of zero mean."""
        A = self.matrix
        if zero_mean:
            b = b - b.mean()
        bnorm = float(np.linalg.norm(b))
        if bnorm == 0.0:
            return np.zeros(self.n), 0, 0.0, True
        # Eigen's CG stops on |r| / |b| < tol; ask for slightly less than our own bound
        cg = ti.linalg.SparseCG(A, b, x0, self.max_iterations, self.tolerance * 0.5)
        with _CaptureFd1() as cap:
            x, _ok = cg.solve()
        m = _ITER.search(cap.text)
        iterations = int(m.group(1)) if m else -1
        x = np.asarray(x, dtype=np.float64)
        if zero_mean:
            x = x - x.mean()
        residual = float(np.linalg.norm(b - A @ x)) / bnorm
        converged = bool(np.isfinite(residual) and residual <= self.tolerance)
        return x, iterations, residual, converged
