"""Steady seepage under a sheet pile and Terzaghi's heave criterion (configs/sheetpile.yaml,
docs/sheetpile.md): the reference the model's heave is measured against.

Steady seepage in a homogeneous isotropic bed obeys Laplace's equation for the head h. `head_field`
solves it by finite differences (five-point stencil on cell centres, spacing `h`) for a bed of depth T
over an impermeable floor between impermeable end walls, a pile of thickness t driven to depth D
(impermeable) at mid-length, the bed's surface at head 1 left of the pile and 0 right of it. The head is
linear in the head difference, so this one solve gives the excess head ratio h / dH everywhere.

Terzaghi's prism (Terzaghi 1943, Theoretical Soil Mechanics art. 89; Terzaghi, Peck & Mesri 1996, art.
50): the sand downstream of the pile, D deep and D / 2 wide, heaves when the mean excess head h_a on its
base lifts its submerged weight, gamma_w h_a = gamma' D, so the critical head difference is

    dH_c = (gamma' / gamma_w) D / (h_a / dH),   gamma' / gamma_w = (Gs - 1) (1 - n).

`harr_prism_ratio` is the same mean for a thin pile in a bed of infinite depth, from the conformal map of
the half-plane with a slit (Harr 1962, Groundwater and Seepage, ch. 5): h / dH = Re(arccos(t / D)) / pi,
t = sqrt(z^2 + D^2), z = x + i y measured from the pile's top at the bed surface; the head at the tip is
dH / 2 and the exit gradient at the pile's downstream face dH / (pi D). It checks the finite differences.
"""

from __future__ import annotations

import numpy as np


def head_field(length: float, depth: float, embed: float, pile: float, h: float, at: float | None = None):
    """Head field (ny, nx) for a unit head difference (1 upstream, 0 downstream) on cell centres, NaN in the
    pile, and the cell-centre coordinates (x, z), x from the bed's upstream end, z up from the floor; the
    pile's upstream face at x = `at` (default: the pile at mid-length)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    nx, ny = int(round(length / h)), int(round(depth / h))
    x = (np.arange(nx) + 0.5) * h
    z = (np.arange(ny) + 0.5) * h
    x0 = 0.5 * (length - pile) if at is None else float(at)
    x1 = x0 + pile
    solid = np.zeros((ny, nx), bool)  # the pile's cells inside the bed
    solid[np.ix_(z >= depth - embed, (x > x0) & (x < x1))] = True
    idx = -np.ones((ny, nx), int)
    idx[~solid] = np.arange((~solid).sum())
    n = int((~solid).sum())
    pad = np.pad(idx, 1, constant_values=-1)  # -1 outside the bed: floor, end walls and the surface
    rows, cols = [], []
    diag = np.zeros(n)
    for dj, di in ((0, 1), (0, -1), (1, 0), (-1, 0)):  # neighbours inside the bed: one flux each
        nb = pad[1 + dj:ny + 1 + dj, 1 + di:nx + 1 + di]
        both = (idx >= 0) & (nb >= 0)
        rows.append(idx[both])
        cols.append(nb[both])
        np.add.at(diag, idx[both], -1.0)
    # the bed's surface: the head fixed half a cell above the top row's centres (floor and end walls:
    # no flux, nothing added)
    top = idx[-1]
    rhs = np.zeros(n)
    open_top = top >= 0
    diag[top[open_top]] -= 2.0
    rhs[top[open_top]] -= 2.0 * (x[open_top] < x0)
    r = np.concatenate(rows + [np.arange(n)])
    c = np.concatenate(cols + [np.arange(n)])
    v = np.concatenate([np.ones(sum(len(k) for k in rows)), diag])
    sol = spla.spsolve(sp.csr_matrix((v, (r, c)), shape=(n, n)), rhs)
    head = np.full((ny, nx), np.nan)
    head[~solid] = sol
    return head, x, z


def prism_ratio(length: float, depth: float, embed: float, pile: float, h: float = 0.0025,
                at: float | None = None) -> float:
    """Mean excess head ratio h_a / dH on the base of Terzaghi's prism (depth D, width D / 2, beside the
    pile's downstream face) from the finite-difference flow net (arguments as `head_field`)."""
    head, x, z = head_field(length, depth, embed, pile, h, at)
    x1 = (0.5 * (length - pile) if at is None else float(at)) + pile
    prism = (x > x1) & (x < x1 + 0.5 * embed)
    return float(np.interp(depth - embed, z, np.nanmean(head[:, prism], axis=1)))


def harr_prism_ratio(samples: int = 20001) -> float:
    """h_a / dH on the prism's base for a thin pile in a bed of infinite depth (conformal map; 0.354)."""
    xs = (np.arange(samples) + 0.5) * (0.5 / samples)  # midpoints across the base, in units of D
    t = np.sqrt((xs - 1j) ** 2 + 1.0)
    t = np.where(t.real < 0, -t, t)  # the downstream side maps to Re t > 0
    head = np.real(np.arccos(t + 0j)) / np.pi
    return float(head.mean())


def critical_head_difference(ratio: float, embed: float, gs: float = 2.65, porosity: float = 0.4) -> float:
    """Terzaghi's dH_c = (gamma' / gamma_w) D / (h_a / dH) (m)."""
    return (gs - 1.0) * (1.0 - porosity) * embed / ratio
