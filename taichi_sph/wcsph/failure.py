"""Seepage-failure sequences read from run files of mode wcsph_biot (configs/embankment.yaml,
configs/sheetpile.yaml; docs/levee.md, docs/sheetpile.md): where and when the soil first yields, how the
yielded zone climbs, where the phreatic line and the wetting front in a levee stand, and the excess
head on the base of the soil prism behind a sheet pile. Numpy and the run-file reader only; the probes
of the configs carry the crest height, the water on the crest, the river level and the heave as time
series for sweeps (docs/output.md, probes soil_level, plastic_strain, water_depth, water_level)."""

from __future__ import annotations

import numpy as np

from ..io.hdf5 import RunFile

WATER, SOIL = 0, 2


def yield_sequence(path: str, threshold: float = 1e-2) -> dict:
    """Per frame of a run: time, the number of soil particles whose plastic strain exceeds `threshold`,
    the highest of them now (`top_x`, `top_z`; NaN before any), the largest soil displacement since the
    first frame, the largest plastic strain; and `first`, the first frame with a yielded particle: its
    time, the yielded particles' places in the first frame (`x0`), their strains, and `x0_max`, the place
    of the most strained of them."""
    out = {"time": [], "n_yielded": [], "top_z": [], "top_x": [], "max_disp": [], "max_strain": [],
           "first": None}
    with RunFile(path) as rf:
        soil = np.asarray(rf.kind) == SOIL
        x0 = np.asarray(rf.field("position", 0), float)[soil]
        for i in range(rf.n_frames):
            x = np.asarray(rf.field("position", i), float)[soil]
            eps = np.asarray(rf.field("plastic_strain", i), float)[soil]
            y = eps > threshold
            out["time"].append(float(rf.times[i]))
            out["n_yielded"].append(int(y.sum()))
            out["max_disp"].append(float(np.linalg.norm(x - x0, axis=1).max()))
            out["max_strain"].append(float(eps.max()))
            if y.any():
                k = int(np.argmax(np.where(y, x[:, -1], -np.inf)))
                out["top_z"].append(float(x[k, -1]))
                out["top_x"].append(float(x[k, 0]))
                if out["first"] is None:
                    out["first"] = {"time": float(rf.times[i]), "x0": x0[y].tolist(),
                                    "strain": eps[y].tolist(), "x0_max": x0[int(np.argmax(eps))].tolist()}
            else:
                out["top_z"].append(float("nan"))
                out["top_x"].append(float("nan"))
    return out


def phreatic_line(position: np.ndarray, kind: np.ndarray, active: np.ndarray, dx: float):
    """Phreatic line of a frame, per soil column dx wide (columns floor(x / dx)): the column centres, the
    soil's top (its highest particle plus dx / 2) and the phreatic height, the highest water particle in
    the column at or below the soil's top plus dx / 2 (0 where the column's pores hold no water)."""
    pos = np.asarray(position, float)
    kind = np.asarray(kind)
    act = np.asarray(active, bool)
    soil = pos[(kind == SOIL) & act]
    water = pos[(kind == WATER) & act]
    cs = np.floor(soil[:, 0] / dx).astype(np.int64)
    c0 = int(cs.min())
    n = int(cs.max()) - c0 + 1
    top = np.full(n, -np.inf)
    np.maximum.at(top, cs - c0, soil[:, -1])
    cw = np.floor(water[:, 0] / dx).astype(np.int64) - c0
    ok = (cw >= 0) & (cw < n)
    cw, zw = cw[ok], water[ok, -1]
    inside = zw <= top[cw] + 0.5 * dx
    table = np.full(n, -np.inf)
    np.maximum.at(table, cw[inside], zw[inside])
    has = np.isfinite(top)
    centres = (np.arange(n) + c0 + 0.5) * dx
    heights = np.where(np.isfinite(table), table + 0.5 * dx, 0.0)
    return centres[has], top[has] + 0.5 * dx, heights[has]


def wetting_front(path: str, dx: float, x_from: float) -> dict:
    """Per frame: the wetting front's foot, the farthest water particle along x beyond `x_from` inside the
    soil (below its column's top) and within 1.5 dx of the floor; and the phreatic line (`phreatic_line`)
    over the columns beyond `x_from` as they stood in the first frame (`columns`, heights in `table`)."""
    out = {"time": [], "front": [], "columns": None, "table": []}
    with RunFile(path) as rf:
        kind = np.asarray(rf.kind)
        cols = None
        for i in range(rf.n_frames):
            pos = np.asarray(rf.field("position", i), float)
            act = np.asarray(rf.field("active", i), bool)
            x, top, h = phreatic_line(pos, kind, act, dx)
            if cols is None:
                cols = x[x > x_from]
                out["columns"] = cols.tolist()
            heights = np.interp(cols, x, h, left=0.0, right=0.0)
            water = pos[(kind == WATER) & act]
            near = water[(water[:, -1] < 1.5 * dx) & (water[:, 0] > x_from)]
            below = near[:, -1] <= np.interp(near[:, 0], x, top, left=-1.0, right=-1.0)
            foot = near[below]
            out["time"].append(float(rf.times[i]))
            out["front"].append(float(foot[:, 0].max()) if len(foot) else float("nan"))
            out["table"].append(heights.tolist())
    return out


def excess_head_on_base(path: str, probes: list[str], base: float, tail_probe: str, rho_w: float = 1000.0,
                        g: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """Mean excess head (m) over the pressure probes on a heave prism's base at height `base`: p / (rho_w
    g) + base less the downstream water level (probe `tail_probe`), at the probes' sample times."""
    with RunFile(path) as rf:
        pr = rf.probes()
        t, _ = pr[probes[0]]
        p = np.mean([np.asarray(pr[n][1], float) for n in probes], axis=0)
        tt, tail = pr[tail_probe]
        tail = np.interp(t, tt, np.asarray(tail, float))
    return np.asarray(t, float), p / (rho_w * g) + base - tail
