"""PPE solver benchmark: SparseMatrixBuilder + SparseCG against EllPCG on the same SPH-like matrices.

The matrices are those of the isph PPE on a patch of water at rest: particles on a jittered square or
cubic lattice (spacing dx, jitter +-0.1 dx), pair coefficients K_ij = -2 dx^d r dW/dr / (r^2 + eta^2)
from the cubic spline of kernels.py (support 2.4 dx), Dirichlet rows for the top two layers (the free
surface), the sides and bottom closed (Neumann: no entries, as walls add only known terms). Both paths
compute the entries in a Taichi kernel from the positions and an explicit neighbour list, as the solver
does. Two scenarios: from x = 0, and the next time step (sources changed by about 1 %, warm start from
the previous solution, as the solver starts from the last pressure).

- sparse: fill a SparseMatrixBuilder, build(), SparseCG (Eigen CG with a diagonal preconditioner)
  through the project's SparseCGSolver wrapper (it asks Eigen for tol / 2 and checks |b - A x| / |b|);
- ell:    fill an EllPCG row by row, then its Jacobi-PCG; once with the ELL width set to the largest
          neighbour count, once with the width of the default neighbour-list capacity (the width
          costs memory traffic: rows are strided by it);
- mg:     the same ELL fill into an MGPCG (width = the largest neighbour count), each row given the
          cell of edge 2.4 dx of its particle (the neighbour grid's), then the multigrid-PCG; its solve
          time includes the set-up of the hierarchy (Galerkin products), also given apart.

Both stop at the same relative residual 1e-8, f64, CPU. Times are the best of --repeat runs after a
warm-up (JIT compilation excluded). Prints Markdown tables naming the machine and its load average.

    python tools/bench_ppe.py [--repeat 3] [--threads N] [--sizes 5k,20k,80k,3d20k,...]
"""

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from bench import (
    machine,  # tools/bench.py: CPU model, cores, OS (run from the repository root)
)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TOLERANCE = 1.0e-8
#: neighbour-list capacity of the config defaults (`neighbours.max`), by dimension
WIDE = {2: 64, 3: 160}
#: name -> lattice shape (the last axis is vertical)
CASES = {
    "5k": (71, 71),
    "20k": (141, 142),
    "80k": (283, 283),
    "3d20k": (27, 27, 27),
    # the step benchmark's hydrostatic sizes (S, M, L of tools/bench.py), for the multigrid's growth
    "10k": (100, 100),
    "50k": (224, 224),
    "200k": (447, 447),
    "3d10k": (22, 22, 22),
    "3d50k": (37, 37, 37),
    "3d200k": (58, 58, 58),
}


def lattice_particles(shape, dx, jitter, seed):
    """Jittered lattice positions, Dirichlet flags (top two layers), neighbour lists within 2.4 dx,
    and a right-hand-side source (a uniform part plus noise, as a divergence source would be)."""
    from scipy.spatial import cKDTree

    from taichi_sph.sph import kernels

    rng = np.random.default_rng(seed)
    grids = np.meshgrid(*[np.arange(s) for s in shape], indexing="ij")
    idx = np.stack([g.ravel() for g in grids], axis=1)
    x = (idx + rng.uniform(-jitter, jitter, idx.shape)) * dx
    dirichlet = (idx[:, -1] >= shape[-1] - 2).astype(np.int32)
    lists = cKDTree(x).query_ball_point(x, kernels.SUPPORT_FACTOR * dx)
    lists = [[j for j in nb if j != i] for i, nb in enumerate(lists)]
    max_nb = max(len(nb) for nb in lists)
    nbr = np.full((len(x), max_nb), -1, dtype=np.int32)
    count = np.zeros(len(x), dtype=np.int32)
    for i, nb in enumerate(lists):
        nbr[i, : len(nb)] = nb
        count[i] = len(nb)
    source = -(1.0 + 0.5 * rng.random(len(x)))
    return x, dirichlet, nbr, count, source, max_nb


def make_problem(shape, dx=0.01, jitter=0.1, seed=0):
    import taichi as ti

    from taichi_sph.sph import kernels

    x_np, dir_np, nbr_np, cnt_np, src_np, max_nb = lattice_particles(shape, dx, jitter, seed)
    n, dim = x_np.shape
    h = 0.5 * kernels.SUPPORT_FACTOR * dx
    eta2 = 1.0e-4 * h * h
    vol = dx**dim

    @ti.data_oriented
    class Problem:
        def __init__(self):
            self.n = n
            self.max_nb = max_nb
            self.x = ti.Vector.field(dim, float, n)
            self.dirichlet = ti.field(ti.i32, n)
            self.nbr = ti.field(ti.i32, (n, max_nb))
            self.count = ti.field(ti.i32, n)
            self.source = ti.field(float, n)
            self.b = ti.field(float, n)
            self.triplets = ti.field(ti.i32, ())
            self.dirichlet_diag = ti.field(float, ())
            self.x.from_numpy(x_np)
            self.dirichlet.from_numpy(dir_np)
            self.nbr.from_numpy(nbr_np)
            self.count.from_numpy(cnt_np)
            self.source.from_numpy(src_np)
            # a Dirichlet row carries the diagonal of a full interior row (as the isph solver does)
            self.dirichlet_diag[None] = self._full_row_diag()

        def _full_row_diag(self):
            offs = np.stack(np.meshgrid(*[np.arange(-3, 4)] * dim, indexing="ij"), -1).reshape(-1, dim)
            r = np.linalg.norm(offs, axis=1) * dx
            r = r[r > 0]
            return float(np.sum(-2.0 * vol * kernels.dw_dr_np(r, h, dim) * r / (r * r + eta2)))

        @ti.func
        def pair(self, i, j):
            rij = self.x[i] - self.x[j]
            r = rij.norm()
            return -2.0 * vol * kernels.dw_dr(r, h, dim) * r / (r * r + eta2)

        @ti.kernel
        def fill_builder(self, A: ti.types.sparse_matrix_builder()):
            self.triplets[None] = 0
            for i in range(self.n):
                if self.dirichlet[i] == 1:
                    A[i, i] += self.dirichlet_diag[None]
                    self.triplets[None] += 1
                    self.b[i] = 0.0
                else:
                    diag = 0.0
                    for k in range(self.count[i]):
                        j = self.nbr[i, k]
                        kij = self.pair(i, j)
                        diag += kij
                        if self.dirichlet[j] == 0:
                            A[i, j] += -kij
                            self.triplets[None] += 1
                    A[i, i] += diag
                    self.triplets[None] += 1
                    self.b[i] = self.source[i]

        @ti.kernel
        def fill_ell(self, ell: ti.template()):
            for i in range(self.n):
                ell.start_row(i)
                if self.dirichlet[i] == 1:
                    ell.add(i, i, self.dirichlet_diag[None])
                    ell.b[i] = 0.0
                else:
                    diag = 0.0
                    for k in range(self.count[i]):
                        j = self.nbr[i, k]
                        kij = self.pair(i, j)
                        diag += kij
                        if self.dirichlet[j] == 0:
                            ell.add(i, j, -kij)
                    ell.add(i, i, diag)
                    ell.b[i] = self.source[i]

    return Problem()


def bench_case(name, shape, repeat):
    import taichi as ti

    from taichi_sph.linalg.ell_pcg import EllPCG
    from taichi_sph.linalg.mg_pcg import MGPCG
    from taichi_sph.linalg.sparse_cg import SparseCGSolver
    from taichi_sph.sph import kernels

    prob = make_problem(shape)
    n = prob.n
    dim = len(shape)
    sparse = SparseCGSolver(n, n * (prob.max_nb + 1), ti.f64, TOLERANCE, 10000)
    ells = {"ell": EllPCG(n, prob.max_nb, TOLERANCE, 10000),
            "ell_wide": EllPCG(n, WIDE[dim], TOLERANCE, 10000)}
    # the multigrid's level-1 cells: the neighbour grid's, edge = the kernel support 2.4 dx
    xp = prob.x.to_numpy()
    cc = np.floor((xp - xp.min(axis=0) + 1e-9) / (kernels.SUPPORT_FACTOR * 0.01)).astype(np.int64)
    ncell = tuple(int(v) for v in cc.max(axis=0) + 1)
    mg = MGPCG(n, prob.max_nb, TOLERANCE, 10000, cells=ncell)
    mg.load_cells(np.ravel_multi_index(cc.T, ncell))
    ells["mg"] = mg

    def run_sparse(x0):
        t0 = time.perf_counter()
        prob.fill_builder(sparse.builder)
        sparse.check_triplets(int(prob.triplets[None]))
        sparse.build()
        b = prob.b.to_numpy()
        t1 = time.perf_counter()
        x, it, res, ok = sparse.solve(b, x0)
        t2 = time.perf_counter()
        return {"fill": t1 - t0, "solve": t2 - t1, "iterations": it, "residual": res, "ok": ok, "x": x}

    def run_ell(ell, x0):
        ell.x.from_numpy(x0)  # in a simulation x simply stays in the field: not timed
        t0 = time.perf_counter()
        prob.fill_ell(ell)
        t1 = time.perf_counter()
        it, res, ok = ell.solve(n)
        t2 = time.perf_counter()
        return {"fill": t1 - t0, "solve": t2 - t1, "iterations": it, "residual": res, "ok": ok,
                "x": ell.x.to_numpy(), "setup": getattr(ell, "last_setup_seconds", 0.0)}

    paths = {"sparse": run_sparse, **{k: (lambda x0, e=e: run_ell(e, x0)) for k, e in ells.items()}}

    def measure(x0):
        runs = {k: [] for k in paths}
        for _ in range(repeat):  # interleaved, so that load from elsewhere hits every path alike
            for k, fn in paths.items():
                runs[k].append(fn(x0))
        out = {}
        for k, rs in runs.items():
            best = dict(rs[-1])
            best["fill"] = min(r["fill"] for r in rs)
            best["solve"] = min(r["solve"] for r in rs)
            best["setup"] = min(r.get("setup", 0.0) for r in rs)
            out[k] = best
        xs = out["sparse"].pop("x")
        out["solution_difference"] = max(float(np.linalg.norm(xs - out[k].pop("x")) / np.linalg.norm(xs))
                                         for k in ells)
        return out, xs

    zero = np.zeros(n)
    for fn in paths.values():
        fn(zero)  # warm-up: compiles the kernels
    cold, x_cold = measure(zero)
    # the next time step: sources changed by about 1 %, start from the last solution
    src = prob.source.to_numpy()
    prob.source.from_numpy(src * (1.0 + 0.01 * np.random.default_rng(1).standard_normal(n)))
    warm, _ = measure(x_cold)
    prob.source.from_numpy(src)
    nnz = float(np.mean(ells["ell"].count.to_numpy()[:n])) + 1.0
    return {"case": name, "dim": dim, "rows": n, "max_nb": prob.max_nb, "nnz_per_row": nnz,
            "cold": cold, "warm": warm}


def markdown(results, info) -> str:
    lines = [
        f"PPE solve, f64, relative residual {TOLERANCE:g}, best of the repeats; {info}.",
        ("ell: EllPCG with width = the largest neighbour count; ell wide: width = the neighbour-list default "
         f"({WIDE[2]} in 2D, {WIDE[3]} in 3D). Times in seconds; sparse fill includes build()."),
    ]
    titles = {"cold": "From x = 0:", "warm": "Next time step (sources changed by 1 %, warm start from the last solution):"}
    for scenario in ("cold", "warm"):
        lines += [
            "",
            titles[scenario],
            "",
            ("| case | rows | nnz/row | iterations sparse / ell | sparse fill | sparse solve | sparse total "
             "| ell fill | ell solve | ell total | sparse / ell | ell wide total | sparse / ell wide "
             "| residual sparse / ell | max rel. difference of x |"),
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|",
        ]
        for r in results:
            c = r[scenario]
            s, e, w = c["sparse"], c["ell"], c["ell_wide"]
            ts, te, tw = s["fill"] + s["solve"], e["fill"] + e["solve"], w["fill"] + w["solve"]
            lines.append(
                f"| {r['dim']}D {r['case']} | {r['rows']} | {r['nnz_per_row']:.1f} "
                f"| {s['iterations']} / {e['iterations']} | {s['fill']:.4f} | {s['solve']:.4f} | {ts:.4f} "
                f"| {e['fill']:.4f} | {e['solve']:.4f} | {te:.4f} | {ts / te:.2f} | {tw:.4f} | {ts / tw:.2f} "
                f"| {s['residual']:.1e} / {e['residual']:.1e} | {c['solution_difference']:.1e} |"
            )
    lines += [
        "",
        "Multigrid-PCG (mg) against Jacobi-PCG (ell), the same ELL matrix and fill; mg solve includes the "
        "set-up of its hierarchy (given apart):",
        "",
        "| case | scenario | rows | iterations ell / mg | ell solve | mg set-up | mg solve | ell / mg (solve) "
        "| residual ell / mg |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in results:
        for scenario in ("cold", "warm"):
            e, m = r[scenario]["ell"], r[scenario]["mg"]
            lines.append(f"| {r['dim']}D {r['case']} | {scenario} | {r['rows']} "
                         f"| {e['iterations']} / {m['iterations']} "
                         f"| {e['solve']:.4f} | {m['setup']:.4f} | {m['solve']:.4f} | {e['solve'] / m['solve']:.2f} "
                         f"| {e['residual']:.1e} / {m['residual']:.1e} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="CPU threads (default: all cores)")
    ap.add_argument("--sizes", default=",".join(CASES), help=f"comma-separated subset of {','.join(CASES)}")
    args = ap.parse_args(argv)
    import taichi as ti

    kw = {} if args.threads is None else {"cpu_max_num_threads": args.threads}
    ti.init(arch=ti.cpu, default_fp=ti.f64, log_level=ti.WARN, **kw)
    threads = args.threads or os.cpu_count()
    info = (f"{machine()}, {threads} threads, Taichi {'.'.join(map(str, ti.__version__))}, "
            f"load average {os.getloadavg()[0]:.1f} at start")
    results = []
    for name in args.sizes.split(","):
        results.append(bench_case(name, CASES[name], args.repeat))
        print(f"done {name}: {results[-1]['rows']} rows", file=sys.stderr, flush=True)
    print(markdown(results, info))
    bad = [f"{r['case']} {c}" for r in results for c in ("cold", "warm")
           if not all(r[c][k]["ok"] for k in ("sparse", "ell", "ell_wide", "mg"))]
    if bad:
        print(f"not converged: {', '.join(bad)}", file=sys.stderr)
        return 1
    diffs = [r[c]["solution_difference"] for r in results for c in ("cold", "warm")]
    return 0 if all(math.isfinite(d) for d in diffs) else 1


if __name__ == "__main__":
    sys.exit(main())
