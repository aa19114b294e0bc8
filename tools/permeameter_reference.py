"""Falling-head permeameter: simulated water level above the plug against the scalar ODE of SPEC 5,
a vD + b vD^2 = (g / eps) (h + L) / L, dh/dt = -vD (quasi-steady), and against the same balance with the
inertia of the column and the plug, (h + Cr L) dvD/dt = g (h + L) - eps L (a vD + b vD^2), started from
rest (porosity.falling_head_level(inertia=True)); the column lags the quasi-steady ODE by 2.5-3.3 % of
its height over the first half for that reason alone.

Usage: python tools/permeameter_reference.py RUN.h5 [RUN.h5 ...]   (runs of configs/permeameter.yaml)
Prints t, h_sim, h_ode (quasi-steady, inertial) and the relative differences for one run; for several,
one line each with the largest deviation over the first half of the drainage (h from h0 to h0 / 2)
from either ODE, the numbers the test and docs/isph.md quote, the share of the plug's water flagged
free surface (Dirichlet rows), and, from 0.1 s over the first half, the plug core's water per pore
volume (particles counted, no kernel) and its mean Darcy velocity (the water a plug passes is their
product); then the largest spread between the runs' deviations at one time (runs of one case at
several dt).
The level is the column's free surface (porosity.column_level), not a count of particles.
"""

import sys

import numpy as np
import yaml

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.isph.porosity import column_level, falling_head_deviation


def simulated_level(rf, plug_top):
    """The column's free surface above plug_top in each frame (porosity.column_level)."""
    water = rf.kind == 0
    out = []
    for i in range(rf.n_frames):
        f = rf.frame(i)
        out.append(column_level(f["position"][water & f["active"]][:, -1], plug_top, rf.dx))
    return np.array(out)


def compare(path):
    """Per frame of one run: t, h_sim, h against the quasi-steady ODE and against the one with the column's
    and the plug's inertia, the first-half mask (quasi-steady h >= h0 / 2), and the plug core's
    free-surface share (None without that field), water per pore volume and mean Darcy velocity."""
    with RunFile(path) as rf:
        cfg = yaml.safe_load(rf.config_yaml)
        reg = cfg["soil"]["regions"][0]
        lo, hi = reg["min"][-1], reg["max"][-1]
        h = simulated_level(rf, hi)
        fh = falling_head_deviation(rf.times, h, hi - lo, reg["eps0"], reg["d50"])
        core = (lo + 2.4 * rf.dx, hi - 2.4 * rf.dx)  # the plug away from its top and bottom faces
        # the core's pore volume: its height times the tank's cross-section (the plug fills the tank)
        pores = reg["eps0"] * (core[1] - core[0]) * float(np.prod(cfg["tank"]["size"][:-1]))
        share, fill, vd = [], [], []
        for i in range(rf.n_frames):
            f = rf.frame(i)
            z = f["position"][:, -1]
            sel = (rf.kind == 0) & f["active"] & (z > core[0]) & (z < core[1])
            if "free_surface" in rf.field_names:
                share.append(float(f["free_surface"][sel].mean()) if sel.any() else float("nan"))
            # water counted without a kernel: each particle fills dx^d of pores
            fill.append(sel.sum() * rf.dx ** rf.dim / pores)
            vd.append(float(-f["velocity"][sel][:, -1].mean()) if sel.any() else float("nan"))
        share = np.array(share) if share else None
        return rf.times, h, fh.ref_quasi, fh.ref, fh.first_half, share, np.array(fill), np.array(vd)


def main(paths):
    if len(paths) == 1:
        t, h, ref, ref_i = compare(paths[0])[:4]
        print("     t   h_sim   h_ode  h_inertial  sim/ode-1  sim/inertial-1")
        for ti, hs, ho, hi in zip(t, h, ref, ref_i):
            print(f"{ti:6.3f}  {hs:.4f}  {ho:.4f}  {hi:.4f}      {hs / ho - 1:+.3f}      {hs / hi - 1:+.3f}")
        return
    curves = []
    for p in paths:
        t, h, ref, ref_i, half, share, fill, vd = compare(p)
        dev = h[half] / ref[half] - 1
        dev_i = h[half] / ref_i[half] - 1
        worst = dev[np.argmax(np.abs(dev))]
        worst_i = dev_i[np.argmax(np.abs(dev_i))]
        # fill and velocity past the start from rest, while the column drains through a full plug
        late = half & (t >= 0.1)
        extra = f"  plug core fill {np.nanmean(fill[late]):.3f}, Darcy velocity {np.nanmean(vd[late]):.4f} m/s"
        if share is not None:
            extra += f", free-surface share {np.nanmean(share[half]):.3f}"
        print(f"{p}: largest deviation over the first half {worst:+.3%} (quasi-steady ODE), "
              f"{worst_i:+.3%} (with inertia){extra}")
        curves.append((t[half], dev_i))
    # runs of one case at several dt (or dx): the largest difference between their deviations at one
    # time, over the first half all of them cover (the two references differ by a function of time
    # alone, so the spread is the same against either)
    t_end = min(c[0][-1] for c in curves)
    tt = curves[0][0][curves[0][0] <= t_end]
    devs = np.array([np.interp(tt, tc, dc) for tc, dc in curves])
    spread = devs.max(axis=0) - devs.min(axis=0)
    k = int(np.argmax(spread))
    print(f"spread between the runs: largest {spread[k]:.3%} at t = {tt[k]:.3f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
