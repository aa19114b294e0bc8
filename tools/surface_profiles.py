"""Free-surface profiles of a 2D run (e.g. configs/porous_dambreak.yaml) read two ways, and their error
against measured profiles when a file of them is given.

Usage: python tools/surface_profiles.py RUN.h5 [RUN.h5 ...] [--times 0.4,0.8,1.2,1.6,2.0]
           [--measured PROFILES.csv] [--depth H0] [--column 2] [--plot OUT.png]

For each run and time (the nearest frame), the surface elevation eta(x) in columns --column spacings
wide (default 2: pore water in ground of porosity 0.49 is 1.43 dx apart in 2D, and narrower columns
read the gaps between its particles as dips):

- top: the highest water particle in the column plus dx / 2 (a flat surface's particles sit dx / 2
  below it), whatever it is joined to: spray and drops count;
- body: the same over the water body alone, the particles joined to the floor through chains of water
  particles closer than 0.9 r_e (r_e = 2.4 dx, the support; the mode's own BODY_LINK, so that pore water
  in the ground, 1.43 dx apart at porosity 0.49 in 2D, stays joined) whose lowest member lies within
  r_e of the floor.

Printed per time: the rms of top - body over the columns where the body has water, divided by the
initial depth H0 (the highest water particle at t = 0 plus dx / 2, or --depth): a reading of how much
the spray and detached water lift the "highest particle" surface above the water body, which needs no
measurement. With --measured (a CSV with columns t, x, eta in s and m; a '#' starts a comment) each
measured point is compared with both readings interpolated at its x, and the rms over all points of a
time and over all times is printed, divided by H0: the score of a surface against a laboratory profile.
Columns with no water read the floor (eta = 0).
"""

import argparse
import sys

import numpy as np
import yaml
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from taichi_sph.io.hdf5 import RunFile

SUPPORT = 2.4  # r_e / dx (sph/kernels.SUPPORT_FACTOR)
BODY_LINK = 0.9  # of r_e: two water particles closer than this belong to one body (isph/surface.py)


def water_body(pos: np.ndarray, dx: float, floor: float) -> np.ndarray:
    """Mask of the particles joined to the floor by chains of pairs closer than BODY_LINK r_e."""
    if len(pos) == 0:
        return np.zeros(0, bool)
    link = BODY_LINK * SUPPORT * dx
    pairs = cKDTree(pos).query_pairs(link, output_type="ndarray")
    n = len(pos)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    grounded = np.unique(label[pos[:, 1] - floor < SUPPORT * dx])
    return np.isin(label, grounded)


def profile(pos: np.ndarray, dx: float, edges: np.ndarray, floor: float) -> np.ndarray:
    """Highest particle + dx / 2 in each column [edges[k], edges[k + 1]), the floor where empty."""
    eta = np.full(len(edges) - 1, floor)
    if len(pos):
        col = np.clip(np.digitize(pos[:, 0], edges) - 1, 0, len(edges) - 2)
        np.maximum.at(eta, col, pos[:, 1] + 0.5 * dx)
    return eta


def read_measured(path: str) -> np.ndarray:
    try:
        data = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"surface_profiles: {path}: {exc}") from None
    if data.shape[1] < 3:
        raise SystemExit(f"surface_profiles: {path}: needs three columns t, x, eta")
    return data[:, :3]


def analyse(path: str, times, measured, depth, column=2.0):
    with RunFile(path) as rf:
        if rf.dim != 2:
            raise SystemExit(f"surface_profiles: {path}: a 2D run is needed")
        dx = rf.dx
        water = rf.kind == 0
        cfg = yaml.safe_load(rf.config_yaml)
        length = float(cfg["tank"]["size"][0])  # the tank's inside spans x in [0, L], its floor at z = 0
        floor = 0.0
        w0 = rf.frame(0)["position"][water]
        h0 = depth if depth else float(w0[:, 1].max() + 0.5 * dx - floor)
        x_lo, x_hi = 0.0, length
        edges = np.linspace(x_lo, x_hi, max(int(round((x_hi - x_lo) / (column * dx))), 1) + 1)
        centres = 0.5 * (edges[1:] + edges[:-1])
        rows = []
        all_top, all_body = [], []
        for t in times:
            k = int(np.argmin(np.abs(np.asarray(rf.times) - t)))
            f = rf.frame(k)
            pos = f["position"][water & f["active"]]
            body = water_body(pos, dx, floor)
            top = profile(pos, dx, edges, floor) - floor
            bod = profile(pos[body], dx, edges, floor) - floor
            wet = bod > 0.0
            rms_gap = float(np.sqrt(np.mean((top[wet] - bod[wet]) ** 2)) / h0) if wet.any() else float("nan")
            row = {"t": float(rf.times[k]), "gap": rms_gap, "detached": int(np.sum(~body)), "n": len(pos)}
            if measured is not None:
                m = measured[np.isclose(measured[:, 0], t, atol=0.5 * (rf.times[1] - rf.times[0]) + 1e-9)]
                if len(m):
                    et = np.interp(m[:, 1], centres, top)
                    eb = np.interp(m[:, 1], centres, bod)
                    row["top"] = float(np.sqrt(np.mean((et - m[:, 2]) ** 2)) / h0)
                    row["body"] = float(np.sqrt(np.mean((eb - m[:, 2]) ** 2)) / h0)
                    all_top.append((et - m[:, 2]) ** 2)
                    all_body.append((eb - m[:, 2]) ** 2)
            rows.append((row, centres, top, bod))
        score = None
        if all_top:
            score = (float(np.sqrt(np.mean(np.concatenate(all_top))) / h0),
                     float(np.sqrt(np.mean(np.concatenate(all_body))) / h0))
        return h0, rows, score


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--times", help="comma-separated times (s); default the measured profiles' times, or "
                                    "0.4,0.8,1.2,1.6,2.0")
    ap.add_argument("--measured", help="CSV of measured profiles: t, x, eta (s, m, m)")
    ap.add_argument("--depth", type=float, help="initial depth H0 (m); default from the first frame")
    ap.add_argument("--column", type=float, default=2.0, help="column width in particle spacings (default 2)")
    ap.add_argument("--plot", help="PNG of the profiles (needs matplotlib)")
    args = ap.parse_args(argv)
    measured = read_measured(args.measured) if args.measured else None
    if args.times:
        times = [float(v) for v in args.times.split(",") if v.strip()]
    elif measured is not None:
        times = sorted(set(measured[:, 0].tolist()))
    else:
        times = [0.4, 0.8, 1.2, 1.6, 2.0]
    results = []
    for path in args.runs:
        h0, rows, score = analyse(path, times, measured, args.depth, args.column)
        results.append((path, rows))
        print(f"{path}: H0 {h0:.4f} m")
        for row, *_ in rows:
            line = (f"  t {row['t']:.3f} s: rms(top - body) / H0 {row['gap']:.4f}; "
                    f"{row['detached']} of {row['n']} water particles not in the body")
            if "top" in row:
                line += f"; against the measured: top {row['top']:.4f}, body {row['body']:.4f}"
            print(line)
        gaps = [r["gap"] for r, *_ in rows if np.isfinite(r["gap"])]
        if gaps:
            print(f"  rms over the times of rms(top - body) / H0: {np.sqrt(np.mean(np.square(gaps))):.4f}")
        if score:
            print(f"  score against the measured profiles, rms / H0 over all points: top {score[0]:.4f}, "
                  f"body {score[1]:.4f}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        n = len(times)
        fig, axes = plt.subplots(n, 1, figsize=(7, 1.8 * n), sharex=True)
        for path, rows in results:
            for ax, (row, x, top, bod) in zip(np.atleast_1d(axes), rows):
                ax.plot(x, top, lw=0.8, label=f"{path}: top")
                ax.plot(x, bod, lw=1.2, label=f"{path}: body")
                if measured is not None:
                    m = measured[np.isclose(measured[:, 0], row["t"], atol=1e-3)]
                    ax.plot(m[:, 1], m[:, 2], "k.", ms=3)
                ax.set_ylabel(f"t {row['t']:.2f} s")
        np.atleast_1d(axes)[0].legend(fontsize=6)
        fig.savefig(args.plot, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
