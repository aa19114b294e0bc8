"""Seepage-failure sequences read from run files of mode wcsph_biot (configs/embankment.yaml,
configs/sheetpile.yaml; docs/levee.md, docs/sheetpile.md): where and when the soil first yields, how the
yielded zone climbs, where the wetting front in a dry levee stands, and the head difference at which
the sand behind a sheet pile heaves. Numpy and the run-file reader only; the probes of the configs carry
the same numbers as time series for sweeps (docs/output.md, probes soil_level, plastic_strain,
water_depth)."""

from __future__ import annotations

import numpy as np

from ..io.hdf5 import RunFile

WATER, SOIL = 0, 2


def _kinds(rf: RunFile) -> np.ndarray:
    return np.asarray(rf.kind)


def yield_sequence(path: str, threshold: float = 1e-2) -> dict:
    """Per frame of a run: time, the number of soil particles whose plastic strain exceeds `threshold`,
    the highest of them (its height and x), the largest displacement since the first frame; and the
    first frame's yielded particles (where the yield starts, at their places in the first frame)."""
    out = {"time": [], "n_yielded": [], "top_z": [], "top_x": [], "max_disp": [], "first": None}
    with RunFile(path) as rf:
        soil = _kinds(rf) == SOIL
        x0 = np.asarray(rf.frame(0)["position"], float)[soil]
        for i in range(rf.n_frames):
            f = rf.frame(i)
            x = np.asarray(f["position"], float)[soil]
            eps = np.asarray(f["plastic_strain"], float)[soil]
            y = eps > threshold
            out["time"].append(float(f["time"]))
            out["n_yielded"].append(int(y.sum()))
            out["max_disp"].append(float(np.linalg.norm(x - x0, axis=1).max()))
            if y.any():
                k = int(np.argmax(np.where(y, x[:, -1], -np.inf)))
                out["top_z"].append(float(x[k, -1]))
                out["top_x"].append(float(x[k, 0]))
                if out["first"] is None:
                    out["first"] = {"time": float(f["time"]), "x0": x0[y].tolist(), "strain": eps[y].tolist()}
            else:
                out["top_z"].append(float("nan"))
                out["top_x"].append(float("nan"))
    return out


def wetting_front(path: str, dx: float, x_from: float) -> dict:
    """Per frame: the farthest water particle along x beyond `x_from` inside the soil and within 1.5 dx of
    the floor (the wetting front's foot), and the phreatic height per soil column (the highest water
    particle among the soil of the column plus dx / 2; 0 where the column is dry)."""
    out = {"time": [], "front": [], "columns": None, "table": []}
    with RunFile(path) as rf:
        kind = _kinds(rf)
        x_soil0 = np.asarray(rf.frame(0)["position"], float)[kind == SOIL]
        cols = np.unique(np.round(x_soil0[x_soil0[:, 0] > x_from, 0] / dx).astype(int))
        out["columns"] = (cols * dx).tolist()
        for i in range(rf.n_frames):
            f = rf.frame(i)
            pos = np.asarray(f["position"], float)
            act = np.asarray(f["active"], bool)
            soil = pos[(kind == SOIL) & act]
            water = pos[(kind == WATER) & act]
            # water inside the soil: within dx / 2 of a soil particle's column and below its top
            ci = np.round(water[:, 0] / dx).astype(int)
            top = {}
            for c, z in zip(np.round(soil[:, 0] / dx).astype(int), soil[:, -1]):
                top[c] = max(top.get(c, -np.inf), z)
            inside = np.array([z <= top.get(c, -np.inf) + 0.5 * dx for c, z in zip(ci, water[:, -1])], bool)
            w_in = water[inside & (water[:, 0] > x_from)]
            foot = w_in[w_in[:, -1] < 1.5 * dx]
            out["time"].append(float(f["time"]))
            out["front"].append(float(foot[:, 0].max()) if len(foot) else float("nan"))
            heights = []
            for c in cols:
                zc = w_in[np.round(w_in[:, 0] / dx).astype(int) == c, -1]
                heights.append(float(zc.max() + 0.5 * dx) if zc.size else 0.0)
            out["table"].append(heights)
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
