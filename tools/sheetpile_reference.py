"""Terzaghi's heave criterion for the sand behind a sheet pile, from a flow net of the geometry
(taichi_sph/wcsph/flownet.py: finite differences for Laplace's equation, checked against the conformal
map of a thin pile in a deep bed).

Prints the mean excess head ratio h_a / dH on the base of Terzaghi's prism (depth D, width D / 2 beside
the pile's downstream face), gamma' / gamma_w = (Gs - 1) (1 - n), the critical head difference
dH_c = (gamma' / gamma_w) D / (h_a / dH) and the exit gradient at the pile's downstream face.
Defaults: configs/sheetpile.yaml's bed (0.54 m long from its upstream end wall, 0.20 m deep, the pile
0.03 m thick with its upstream face 0.12 m from that wall, driven D = 0.06 m; the `coarse` variant's pile
is 0.06 m thick: --pile 0.06).

    python tools/sheetpile_reference.py [--length 0.54] [--depth 0.2] [--embed 0.06] [--pile 0.03] [--at 0.12]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from taichi_sph.wcsph.flownet import critical_head_difference, harr_prism_ratio, head_field  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, default=0.54, help="bed length between its end walls (m)")
    ap.add_argument("--depth", type=float, default=0.2, help="bed depth T (m)")
    ap.add_argument("--embed", type=float, default=0.06, help="pile embedment D (m)")
    ap.add_argument("--pile", type=float, default=0.03, help="pile thickness (m)")
    ap.add_argument("--at", type=float, default=0.12, help="the pile's upstream face from the bed's end (m)")
    ap.add_argument("--gs", type=float, default=2.65, help="grain specific gravity Gs")
    ap.add_argument("--porosity", type=float, default=0.4, help="porosity n")
    ap.add_argument("--h", type=float, default=0.0025, help="grid spacing (m)")
    a = ap.parse_args()
    head, x, z = head_field(a.length, a.depth, a.embed, a.pile, a.h, a.at)
    x1 = a.at + a.pile
    base = a.depth - a.embed
    prism = (x > x1) & (x < x1 + 0.5 * a.embed)
    ratio = float(np.interp(base, z, np.nanmean(head[:, prism], axis=1)))
    i_exit = float(head[-1, np.argmax(x > x1)] / (0.5 * a.h))
    print(f"grid {head.shape[1]} x {head.shape[0]} (h = {a.h} m); prism base at z = {base:.4f} m")
    print(f"mean excess head on the prism's base h_a / dH = {ratio:.4f} (thin pile, infinite depth: "
          f"{harr_prism_ratio():.4f})")
    dh_c = critical_head_difference(ratio, a.embed, a.gs, a.porosity)
    print(f"gamma' / gamma_w = {(a.gs - 1) * (1 - a.porosity):.4f}; Terzaghi's critical head difference "
          f"dH_c = {dh_c:.4f} m")
    print(f"exit gradient at the pile's downstream face i_exit / dH = {i_exit:.3f} 1/m")


if __name__ == "__main__":
    main()
