"""Falling-head permeameter: simulated water level above the plug against the scalar ODE of SPEC 5,
a vD + b vD^2 = (g / eps) (h + L) / L, dh/dt = -vD.

Usage: python tools/permeameter_reference.py RUN.h5   (a run of configs/permeameter.yaml)
Prints t, h_sim, h_ode and the relative difference.
"""

import sys

import numpy as np
import yaml

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.isph.porosity import falling_head_level


def simulated_level(rf, plug_top, width):
    """Water above the plug, as a height: particles above plug_top times dx^d / width^(d-1)."""
    water = rf.kind == 0
    out = []
    for i in range(rf.n_frames):
        f = rf.frame(i)
        z = f["position"][water & f["active"]][:, -1]
        out.append((z > plug_top).sum() * rf.dx**rf.dim / width ** (rf.dim - 1))
    return np.array(out)


def main(path):
    with RunFile(path) as rf:
        cfg = yaml.safe_load(rf.config_yaml)
        reg = cfg["soil"]["regions"][0]
        lo, hi = reg["min"][-1], reg["max"][-1]
        width = cfg["tank"]["size"][0]
        h = simulated_level(rf, hi, width)
        sol = falling_head_level(h[0], hi - lo, reg["eps0"], reg["d50"], t_end=rf.times[-1])
        for t, hs in zip(rf.times, h):
            ho = float(sol(t))
            print(f"{t:6.3f}  {hs:.4f}  {ho:.4f}  {hs / ho - 1:+.3f}")


if __name__ == "__main__":
    main(sys.argv[1])
