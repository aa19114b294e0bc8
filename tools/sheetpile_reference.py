"""Terzaghi's heave criterion for the sand behind a sheet pile, from a flow net of the geometry.

Steady seepage in a homogeneous isotropic bed obeys Laplace's equation for the head h. This solves it by
finite differences (five-point stencil, spacing `--h`) for configs/sheetpile.yaml's geometry: a bed of
depth T over an impermeable floor between impermeable end walls, a pile of thickness t driven to depth D
(impermeable), the bed's surface at head H_up left of the pile and H_down right of it. The head is linear
in H_up - H_down, so one solve with a unit difference gives the excess head ratio everywhere.

Terzaghi's prism (Terzaghi 1943; Terzaghi, Peck & Mesri 1996, art. 50): the sand downstream of the pile,
D deep and D / 2 wide, heaves when the mean excess head h_a on its base lifts its submerged weight,
gamma_w h_a = gamma' D, so the critical head difference is

    dH_c = (gamma' / gamma_w) D / (h_a / dH),

with gamma' / gamma_w = (Gs - 1) (1 - n). The script prints h_a / dH on the prism's base and dH_c, and
the exit gradient at the pile's downstream face.

    python tools/sheetpile_reference.py [--depth 0.2] [--embed 0.1] [--length 0.8] [--pile 0.02] [--h 0.0025]
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def excess_head_ratio(length: float, depth: float, embed: float, pile: float, h: float):
    """Head field (ny, nx) for a unit head difference (1 upstream, 0 downstream), on cell centres, and the
    cell-centre coordinates (x, z)."""
    nx, ny = int(round(length / h)), int(round(depth / h))
    x = (np.arange(nx) + 0.5) * h
    z = (np.arange(ny) + 0.5) * h
    x0, x1 = 0.5 * (length - pile), 0.5 * (length + pile)
    solid = np.zeros((ny, nx), bool)  # the pile's cells inside the bed
    solid[np.ix_(z >= depth - embed, (x > x0) & (x < x1))] = True
    idx = -np.ones((ny, nx), int)
    idx[~solid] = np.arange((~solid).sum())
    rows, cols, vals = [], [], []
    rhs = np.zeros((~solid).sum())
    for j in range(ny):
        for i in range(nx):
            k = idx[j, i]
            if k < 0:
                continue
            diag = 0.0
            for dj, di in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                jj, ii = j + dj, i + di
                if 0 <= jj < ny and 0 <= ii < nx:
                    if idx[jj, ii] >= 0:
                        rows.append(k)
                        cols.append(idx[jj, ii])
                        vals.append(1.0)
                        diag -= 1.0
                elif jj == ny:  # the bed's surface: head fixed half a cell above the cell centre
                    head = 1.0 if x[i] < x0 else 0.0
                    diag -= 2.0
                    rhs[k] -= 2.0 * head
                # floor and end walls: no flux (nothing added)
            rows.append(k)
            cols.append(k)
            vals.append(diag)
    a = sp.csr_matrix((vals, (rows, cols)), shape=(len(rhs), len(rhs)))
    sol = spla.spsolve(a, rhs)
    head = np.full((ny, nx), np.nan)
    head[~solid] = sol
    return head, x, z


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--length", type=float, default=0.8, help="bed length between the end walls (m)")
    ap.add_argument("--depth", type=float, default=0.2, help="bed depth T (m)")
    ap.add_argument("--embed", type=float, default=0.1, help="pile embedment D (m)")
    ap.add_argument("--pile", type=float, default=0.02, help="pile thickness (m)")
    ap.add_argument("--gs", type=float, default=2.65, help="grain specific gravity Gs")
    ap.add_argument("--porosity", type=float, default=0.4, help="porosity n")
    ap.add_argument("--h", type=float, default=0.0025, help="grid spacing (m)")
    a = ap.parse_args()
    head, x, z = excess_head_ratio(a.length, a.depth, a.embed, a.pile, a.h)
    x1 = 0.5 * (a.length + a.pile)
    base = a.depth - a.embed
    jb = int(np.argmin(np.abs(z - base)))
    prism = (x > x1) & (x < x1 + 0.5 * a.embed)
    ratio = float(np.interp(base, z, np.nanmean(head[:, prism], axis=1)))
    gamma_ratio = (a.gs - 1.0) * (1.0 - a.porosity)
    dh_c = gamma_ratio * a.embed / ratio
    i_exit = float(head[-1, np.argmax(x > x1)] / (0.5 * a.h))
    print(f"grid {head.shape[1]} x {head.shape[0]} (h = {a.h} m); prism base at z = {z[jb]:.4f} m")
    print(f"mean excess head on the prism's base h_a / dH = {ratio:.4f}")
    print(f"gamma' / gamma_w = {gamma_ratio:.4f}; Terzaghi's critical head difference dH_c = {dh_c:.4f} m")
    print(f"exit gradient at the pile's downstream face i_exit / dH = {i_exit:.3f} 1/m")


if __name__ == "__main__":
    main()
