"""Neighbour search with and without reordering the particle arrays into cell order.

Particles on a jittered lattice (spacing dx, support 2.4 dx, cells of 2.4 dx) are stored in random
order, as after a long run of mixing flow. Both variants bin them with NeighbourGrid's counting sort;
"reorder on" then permutes positions and velocities into cell order (NeighbourGrid.reorder, as the
solvers do every step), "reorder off" leaves them where they are and reaches particles through the
permutation. Then the same kernels build explicit neighbour lists and run two typical passes over
them (a density sum of W, and a force-like sum of (v_j - v_i) grad W). Times are the best of
--repeat, JIT excluded.

    python tools/bench_grid.py [--repeat 5] [--threads N]
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

CASES = {"2D 80k": (283, 283), "3D 64k": (40, 40, 40)}


def make(shape, seed=0):
    import taichi as ti

    from taichi_sph.sph import kernels
    from taichi_sph.sph.grid import NeighbourGrid

    dim = len(shape)
    dx = 0.01
    rng = np.random.default_rng(seed)
    idx = np.stack([g.ravel() for g in np.meshgrid(*[np.arange(s) for s in shape], indexing="ij")], axis=1)
    pos = (idx + 0.5 + rng.uniform(-0.1, 0.1, idx.shape)) * dx
    pos = pos[rng.permutation(len(pos))]  # memory order unrelated to space
    n = len(pos)
    re = kernels.SUPPORT_FACTOR * dx
    h = 0.5 * re
    max_nb = 64 if dim == 2 else 160
    lo, hi = np.zeros(dim), np.asarray(shape) * dx

    @ti.data_oriented
    class Case:
        def __init__(self):
            self.n = n
            self.x = ti.Vector.field(dim, float, n)
            self.v = ti.Vector.field(dim, float, n)
            self.active = ti.field(ti.i32, n)
            self.rho = ti.field(float, n)
            self.acc = ti.Vector.field(dim, float, n)
            self.count = ti.field(ti.i32, n)
            self.nbr = ti.field(ti.i32, (n, max_nb))
            self.grid = NeighbourGrid(n, dim, lo, hi, re, max_nb)

        def reset(self):
            self.x.from_numpy(pos)
            self.v.from_numpy(np.sin(pos * 37.0))
            self.active.fill(1)

        @ti.kernel
        def build(self):
            g = self.grid
            for i in range(self.n):
                xi = self.x[i]
                cc = ti.Vector.zero(ti.i32, dim)
                for d in ti.static(range(dim)):
                    cc[d] = ti.min(ti.cast(xi[d] / re, ti.i32), g.ncell[d] - 1)
                cnt = 0
                for off in ti.static(ti.grouped(ti.ndrange(*([(-1, 2)] * dim)))):
                    c = cc + off
                    inside = True
                    for d in ti.static(range(dim)):
                        if c[d] < 0 or c[d] >= g.ncell[d]:
                            inside = False
                    if inside:
                        lin = 0
                        for d in ti.static(range(dim)):
                            lin = lin * g.ncell[d] + c[d]
                        for k in range(g.cell_start[lin], g.cell_start[lin + 1]):
                            j = g.perm[k]
                            if j != i and (xi - self.x[j]).norm_sqr() < re * re and cnt < max_nb:
                                self.nbr[i, cnt] = j
                                cnt += 1
                self.count[i] = cnt

        @ti.kernel
        def density(self):
            for i in range(self.n):
                s = kernels.w(0.0, h, dim)
                for k in range(self.count[i]):
                    s += kernels.w((self.x[i] - self.x[self.nbr[i, k]]).norm(), h, dim)
                self.rho[i] = s

        @ti.kernel
        def force(self):
            for i in range(self.n):
                a = ti.Vector.zero(float, dim)
                for k in range(self.count[i]):
                    j = self.nbr[i, k]
                    rij = self.x[i] - self.x[j]
                    r = rij.norm()
                    if r > 0.0:
                        a += (self.v[j] - self.v[i]) * kernels.dw_dr(r, h, dim) / r * rij.dot(rij)
                self.acc[i] = a

    return Case()


def run(case, reorder: bool, repeat: int) -> dict:
    import taichi as ti

    best = {}
    for _ in range(repeat + 1):  # the first round compiles
        case.reset()
        t = {}
        ti.sync()
        t0 = time.perf_counter()
        case.grid.sort(case.x, case.active, case.n)
        ti.sync()
        t["sort"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        if reorder:
            for f in (case.x, case.v):
                case.grid.reorder(f, case.n)
            case.grid.sort(case.x, case.active, case.n)  # cell ranges of the new order (perm = identity)
        ti.sync()
        t["reorder"] = time.perf_counter() - t0
        for name in ("build", "density", "force"):
            t0 = time.perf_counter()
            getattr(case, name)()
            ti.sync()
            t[name] = time.perf_counter() - t0
        for k, v in t.items():
            best[k] = min(best.get(k, np.inf), v)
    best["total"] = sum(best.values())
    best["rho_sum"] = float(case.rho.to_numpy().sum())
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    import taichi as ti
    from bench import machine

    kw = {} if args.threads is None else {"cpu_max_num_threads": args.threads}
    ti.init(arch=ti.cpu, default_fp=ti.f64, log_level=ti.WARN, **kw)
    print(f"{machine()}, {args.threads or os.cpu_count()} threads, f64, load average {os.getloadavg()[0]:.1f}; "
          f"best of {args.repeat}, ms")
    print()
    print("| case | reorder | sort | reorder | list build | density pass | force pass | total | off / on |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, shape in CASES.items():
        case = make(shape)
        on = run(case, True, args.repeat)
        off = run(case, False, args.repeat)
        assert abs(on["rho_sum"] - off["rho_sum"]) <= 1e-9 * abs(on["rho_sum"])  # same sums, other order
        for label, r in (("on", on), ("off", off)):
            ratio = f"{off['total'] / on['total']:.2f}" if label == "off" else ""
            print(f"| {name} | {label} | " + " | ".join(f"{1e3 * r[k]:.2f}" for k in
                  ("sort", "reorder", "build", "density", "force", "total")) + f" | {ratio} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
