"""Memory bandwidth of the PPE's conjugate-gradient iteration against the device's stream bandwidth.

The PPE solve (taichi_sph/linalg/ell_pcg.py, Jacobi-PCG on an ELL matrix) is bound by memory traffic:
each iteration streams the matrix once and a handful of vectors. This tool measures

- the device's stream bandwidth: a Taichi copy kernel `dst[i] = src[i]` over `--copy-mb` MB per array,
  bytes read plus bytes written per second (best of several);
- the CG iteration: the PPE matrix of water at rest on a regular lattice (spacing dx, neighbours within
  the kernel support 2.4 dx: 20 in 2D, 56 in 3D, the pair coefficients of the isph PPE, the top two
  layers Dirichlet, the other sides closed), filled into an EllPCG in a kernel; then a fixed number of
  iterations timed (`EllPCG._iterate`, one launch each with its scalar back to the host, as the solver
  runs them). Bytes per iteration, counting every array element the iteration must touch once:

      p = z + beta p               3 n f                    (read z, p; write p)
      Ap, p.Ap                     n (4 + 3 f) + nnz (4 + f) (count, diag, p_i, ap; per entry column and value)
      x, r, z, r.r, r.z            8 n f                    (read x, p, r, ap, 1/diag; write x, r, z)

  with f the float's size and nnz the off-diagonal entries; the gathered p_j are taken as cache hits
  (on a lattice ordered row by row they are mostly), so this is the least traffic the iteration needs
  and bytes / time is the bandwidth it achieves. Reported against the copy kernel's.

Both ELL layouts ("row": a row's slots together; "column": slot k of consecutive rows together) and f32
and f64 are run, each with the solver's reduction (`reduction="auto"`: two-stage
dot products on CUDA), or with those named by `--reductions`.

Each case is timed twice: one launch per iteration with |r|^2 read back after each (the solver's way
with `batch` 1), and in batches of `--batch` launches with the convergence state read once per batch
(EllPCG's `batch`, its CUDA default), where the host queues the launches without waiting on each.

    python tools/bench_ppe_bandwidth.py [--arch cuda] [--sizes 2d1m 2d4m 3d1m] [--iterations 200] [--batch 8]
        [--reductions auto atomic two_stage]
"""


import argparse
import itertools
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: name -> lattice shape (last axis vertical)
SIZES = {
    "2d250k": (500, 500),
    "2d1m": (1000, 1000),
    "2d4m": (2000, 2000),
    "3d250k": (63, 63, 63),
    "3d1m": (100, 100, 100),
}


def copy_bandwidth(ti, megabytes: float, dtype, repeat: int = 10) -> float:
    """Bytes read + written per second by a copy kernel over arrays of `megabytes` each."""
    itemsize = 8 if dtype == ti.f64 else 4
    n = int(megabytes * 1e6 / itemsize)
    src = ti.field(dtype, n)
    dst = ti.field(dtype, n)

    @ti.kernel
    def fill():
        for i in range(n):
            src[i] = ti.cast(i % 7, dtype)

    @ti.kernel
    def copy():
        for i in range(n):
            dst[i] = src[i]

    fill()
    copy()
    ti.sync()
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        copy()
        ti.sync()
        best = min(best, time.perf_counter() - t0)
    return 2.0 * n * itemsize / best


def lattice_offsets(dim: int):
    """Lattice offsets within the kernel support (r < 2.4 dx), and the PPE pair coefficient of each."""
    from taichi_sph.sph import kernels

    dx = 1.0
    h = 0.5 * kernels.SUPPORT_FACTOR * dx
    eta2 = 1.0e-4 * h * h
    offs = [o for o in itertools.product(range(-3, 4), repeat=dim)
            if 0 < math.sqrt(sum(c * c for c in o)) < kernels.SUPPORT_FACTOR]
    r = np.array([math.sqrt(sum(c * c for c in o)) for o in offs])
    coef = -2.0 * dx**dim * kernels.dw_dr_np(r, h, dim) * r / (r * r + eta2)
    return offs, [float(c) for c in coef]


def bench_size(ti, name: str, shape, dtype, layout: str, iterations: int, reduction: str = "auto",
               batch: int = 8) -> dict:
    from taichi_sph.linalg.ell_pcg import EllPCG

    dim = len(shape)
    n = int(np.prod(shape))
    offs, coef = lattice_offsets(dim)
    width = len(offs)
    ell = EllPCG(n, width, tolerance=1e-30, max_iterations=iterations, dtype=dtype, layout=layout,
                 reduction=reduction, batch=batch)
    strides = [int(np.prod(shape[k + 1:])) for k in range(dim)]
    top = shape[-1]
    off_f = ti.Vector.field(dim, ti.i32, width)
    coef_f = ti.field(ti.f64, width)
    off_f.from_numpy(np.array(offs, dtype=np.int32))
    coef_f.from_numpy(np.array(coef))

    @ti.kernel
    def fill(e: ti.template()):
        for i in range(n):
            idx = ti.Vector([(i // strides[k]) % shape[k] for k in ti.static(range(dim))])
            e.start_row(i)
            e.x[i] = ti.cast(0, dtype)
            if idx[dim - 1] >= top - 2:  # free surface: Dirichlet row
                e.add(i, i, 1.0)
                e.b[i] = ti.cast(0, dtype)
            else:
                diag = 0.0
                for k in range(width):
                    j_idx = idx + off_f[k]
                    inside = True
                    for c in ti.static(range(dim)):
                        if j_idx[c] < 0 or j_idx[c] >= shape[c]:
                            inside = False
                    if inside:
                        diag += coef_f[k]
                        if j_idx[dim - 1] < top - 2:
                            j = 0
                            for c in ti.static(range(dim)):
                                j += j_idx[c] * strides[c]
                            e.add(i, j, -coef_f[k])
                e.add(i, i, diag)
                e.b[i] = ti.cast(-1, dtype)

    t0 = time.perf_counter()
    fill(ell)
    ti.sync()
    fill_s = time.perf_counter() - t0
    ell.n[None] = n
    nnz = int(np.minimum(ell.count.to_numpy(), width).sum())
    ell._restart()
    for _ in range(3):  # warm-up (compiles)
        ell._iterate()
    ell._restart()
    ti.sync()
    t0 = time.perf_counter()
    for _ in range(iterations):
        ell._iterate()
    ti.sync()
    per_iter = (time.perf_counter() - t0) / iterations
    # the same iterations in batches of `batch` launches, the convergence state read once per batch
    # (EllPCG's `batch`, the CUDA default): the launches queue without the host waiting on each
    ell._restart()
    ell._iterate_batched(0.0, 2)  # warm-up (compiles)
    ell._restart()
    ti.sync()
    t0 = time.perf_counter()
    ell._iterate_batched(0.0, iterations)  # threshold 0: runs on to the limit, as the loop above
    ti.sync()
    per_iter_batched = (time.perf_counter() - t0) / iterations
    f = 8 if dtype == ti.f64 else 4
    nbytes = 3 * n * f + n * (4 + 3 * f) + nnz * (4 + f) + 8 * n * f
    return {"case": name, "rows": n, "dim": dim, "precision": "f64" if dtype == ti.f64 else "f32", "layout": layout,
            "reduction": ell.reduction, "nnz_per_row": nnz / n, "ms_per_iteration": 1e3 * per_iter,
            "batch": batch, "ms_per_iteration_batched": 1e3 * per_iter_batched, "bytes_per_iteration": nbytes,
            "gb_per_s": nbytes / per_iter / 1e9, "fill_s_first": fill_s}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default="cuda", choices=["cpu", "cuda"])
    ap.add_argument("--sizes", nargs="+", default=["2d1m", "2d4m", "3d1m"], choices=list(SIZES))
    ap.add_argument("--precisions", nargs="+", default=["f32", "f64"], choices=["f32", "f64"])
    ap.add_argument("--layouts", nargs="+", default=["column", "row"], choices=["column", "row"])
    ap.add_argument("--reductions", nargs="+", default=["auto"], choices=["auto", "atomic", "two_stage"])
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--batch", type=int, default=8, help="launches per read of the convergence state in the "
                    "batched timing (EllPCG's batch)")
    ap.add_argument("--copy-mb", type=float, default=1024.0, help="MB per array of the copy kernel")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    import taichi as ti

    ti.init(arch=ti.cuda if args.arch == "cuda" else ti.cpu, default_fp=ti.f64, log_level=ti.WARN)
    copy = {p: copy_bandwidth(ti, args.copy_mb, ti.f64 if p == "f64" else ti.f32) for p in args.precisions}
    print(json.dumps({"copy_gb_per_s": {p: v / 1e9 for p, v in copy.items()}}), flush=True)
    rows = []
    for name in args.sizes:
        for prec in args.precisions:
            for layout in args.layouts:
                for reduction in args.reductions:
                    r = bench_size(ti, name, SIZES[name], ti.f64 if prec == "f64" else ti.f32, layout,
                                   args.iterations, reduction, args.batch)
                    r["fraction_of_copy"] = r["gb_per_s"] * 1e9 / copy[prec]
                    rows.append(r)
                    print(json.dumps(r), flush=True)
    lines = [f"Arch {args.arch}; copy kernel: " + ", ".join(f"{p} {v / 1e9:.0f} GB/s" for p, v in copy.items()), "",
             ("| lattice | rows | entries/row | precision | layout | reduction | ms / iteration | ms / iteration, "
              f"batches of {args.batch} | MB / iteration | GB/s | of copy |"),
             "|---|---:|---:|---|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['rows']} | {r['nnz_per_row'] + 1:.1f} | {r['precision']} | {r['layout']} | "
                     f"{r['reduction']} | {r['ms_per_iteration']:.3f} | {r['ms_per_iteration_batched']:.3f} | "
                     f"{r['bytes_per_iteration'] / 1e6:.0f} | {r['gb_per_s']:.0f} | "
                     f"{100 * r['fraction_of_copy']:.0f} % |")
    print("\n".join(lines))
    if args.json:
        args.json.write_text(json.dumps({"copy_bytes_per_s": copy, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
