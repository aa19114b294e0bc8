"""Numbers of the seepage-failure cases (docs/levee.md, docs/sheetpile.md) from their run files.

    python tools/seepage_failure.py levee STAGE1.h5 STAGE2.h5 [--toe 2.2] [--crest 0.15] [--dx 0.01]
    python tools/seepage_failure.py dry RUN.h5 [--entry 1.55] [--head 0.12] [--k 0.05] [--porosity 0.4]
    python tools/seepage_failure.py sheetpile RUN.h5 [--embed 0.06] [--bed 0.2] [--face 1.23]

levee: stage 1's largest displacement and plastic strain; stage 2's first yielded particle (plastic
strain > 1e-2) with its distance from the landside toe, the highest yielded point over time, the first
time water stands on the crest and the crest's lowest height (probes `overflow`, `crest`).
dry: the wetting front's foot against the Boussinesq solution x_f = 1.62 sqrt(k H t / n) from the
entry face, the advance exponent, and the phreatic line's curvature (convex downward: the line's
second difference over x is positive where it is wet).
sheetpile: the head difference at heave (the mean surface over the prism's width D up by 1 mm), the
mean excess head on the prism's base from the run's own pressures just before heave, and Terzaghi's
critical head difference from both that head and the flow net (tools/sheetpile_reference.py).
Each prints a table and, with --json FILE, writes the numbers.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from taichi_sph.io.hdf5 import RunFile  # noqa: E402
from taichi_sph.wcsph import failure  # noqa: E402
from taichi_sph.wcsph.dupuit import boussinesq_front, boussinesq_front_coefficient  # noqa: E402


def levee(a) -> dict:
    s1 = failure.yield_sequence(a.stage1, 1e-3)
    with RunFile(a.stage1) as rf:
        eps1 = float(max(np.max(rf.frame(i)["plastic_strain"]) for i in range(rf.n_frames)))
    seq = failure.yield_sequence(a.stage2, 1e-2)
    out = {"stage1_max_disp_mm": 1e3 * s1["max_disp"][-1], "stage1_max_plastic_strain": eps1}
    first = seq["first"]
    if first:
        x0 = np.asarray(first["x0"])
        d_toe = np.abs(x0[:, 0] - a.toe) + x0[:, -1]  # along the floor to the toe, then up
        out["first_yield_time"] = first["time"]
        out["first_yield_points"] = x0.tolist()
        out["first_yield_dist_to_landside_toe_dx"] = float(d_toe.min() / a.dx)
    t = np.asarray(seq["time"])
    top = np.asarray(seq["top_z"])
    wet = np.isfinite(top)
    out["yield_top"] = [[float(ti), float(zi), float(xi)] for ti, zi, xi in zip(t[wet], top[wet],
                                                                              np.asarray(seq["top_x"])[wet])]
    # monotone within 2 dx: the running maximum never exceeds a later reading by more than 2 dx
    if wet.any():
        run_max = np.maximum.accumulate(top[wet])
        out["yield_top_largest_drop_dx"] = float(np.max(run_max - top[wet]) / a.dx)
    with RunFile(a.stage2) as rf:
        pr = rf.probes()
    if "overflow" in pr:
        to, depth = pr["overflow"]
        over = np.flatnonzero(np.asarray(depth) > 0.5 * a.dx)
        out["overflow_time"] = float(to[over[0]]) if over.size else math.nan
    if "crest" in pr:
        tc, crest = (np.asarray(v, float) for v in pr["crest"])
        out["crest_start"] = float(crest[0])
        out["crest_min"] = float(crest.min())
        out["crest_fall_pct"] = 100.0 * (crest[0] - crest.min()) / crest[0]
        below = np.flatnonzero(crest < 0.8 * crest[0])
        out["crest_fall_20pct_time"] = float(tc[below[0]]) if below.size else math.nan
    if "river" in pr:
        tr, river = (np.asarray(v, float) for v in pr["river"])
        out["river_level"] = [[float(x), float(y)] for x, y in zip(tr[::20], river[::20])]
    return out


def dry(a) -> dict:
    wf = failure.wetting_front(a.run, a.dx, a.entry - 0.5 * a.dx)
    t = np.asarray(wf["time"])
    front = np.asarray(wf["front"]) - a.entry
    ref = boussinesq_front(a.k, a.porosity, a.head, t)
    ok = np.isfinite(front) & (t > 0) & (front > 2 * a.dx) & (front + a.entry < a.toe - 2 * a.dx)
    out = {"eta_f": boussinesq_front_coefficient(), "rows": []}
    for ti, fi, ri in zip(t[ok], front[ok], ref[ok]):
        out["rows"].append([float(ti), float(fi), float(ri), float(fi / ri - 1.0)])
    if ok.sum() >= 3:
        p = np.polyfit(np.log(t[ok]), np.log(front[ok]), 1)
        out["advance_exponent"] = float(p[0])
        out["largest_error_pct"] = float(100 * np.max(np.abs(front[ok] / ref[ok] - 1.0)))
    # phreatic line shape at three times: second differences of the wet part
    cols = np.asarray(wf["columns"])
    shapes = []
    for i in np.flatnonzero(ok)[[0, len(np.flatnonzero(ok)) // 2, -1]] if ok.sum() >= 3 else []:
        h = np.asarray(wf["table"][i])
        wet = h > 0
        d2 = np.diff(h[wet], 2)
        shapes.append({"time": float(t[i]), "x": cols[wet].tolist(), "h": h[wet].tolist(),
                       "convex_share": float(np.mean(d2 > -1e-9)) if d2.size else math.nan})
    out["shapes"] = shapes
    return out


def sheetpile(a) -> dict:
    with RunFile(a.run) as rf:
        pr = rf.probes()
    th, heave = (np.asarray(v, float) for v in pr["heave"])
    lift = heave - heave[0]
    up = np.flatnonzero(lift > 1e-3)
    out = {"heave_time": float(th[up[0]]) if up.size else math.nan}
    tu, hu = (np.asarray(v, float) for v in pr["h_upstream"])
    td, hd = (np.asarray(v, float) for v in pr["h_downstream"])
    dh = np.interp(th, tu, hu) - np.interp(th, td, hd)
    out["dH_series"] = [[float(x), float(y), float(z)] for x, y, z in zip(th[::10], dh[::10], lift[::10])]
    base = a.bed - a.embed
    tb, ha = failure.excess_head_on_base(a.run, ["p_base_1", "p_base_2", "p_base_3"], base, "h_downstream")
    ratio = np.interp(th, tb, ha) / np.where(np.abs(dh) > 1e-9, dh, np.nan)
    gamma = (a.gs - 1.0) * (1.0 - a.porosity)
    if up.size:
        k = max(up[0] - 1, 0)  # the sample just before heave
        out["dH_at_heave"] = float(dh[up[0]])
        out["h_a_before_heave"] = float(np.interp(th[k], tb, ha))
        out["h_a_ratio_model"] = float(ratio[k])
        out["dH_c_model_field"] = float(gamma * a.embed / ratio[k])
    from sheetpile_reference import excess_head_ratio

    head, x, z = excess_head_ratio(a.length, a.bed, a.embed, a.pile, 0.0025)
    prism = (x > 0.5 * (a.length + a.pile)) & (x < 0.5 * (a.length + a.pile) + 0.5 * a.embed)
    r_net = float(np.interp(base, z, np.nanmean(head[:, prism], axis=1)))
    out["h_a_ratio_flownet"] = r_net
    out["dH_c_flownet"] = float(gamma * a.embed / r_net)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="case", required=True)
    lv = sub.add_parser("levee")
    lv.add_argument("stage1")
    lv.add_argument("stage2")
    lv.add_argument("--toe", type=float, default=2.2, help="x of the landside toe (m)")
    lv.add_argument("--dx", type=float, default=0.01)
    dr = sub.add_parser("dry")
    dr.add_argument("run")
    dr.add_argument("--entry", type=float, default=1.55, help="x of the river's entry face (m)")
    dr.add_argument("--toe", type=float, default=2.2, help="x of the landside toe (m)")
    dr.add_argument("--head", type=float, default=0.12, help="river level H (m)")
    dr.add_argument("--k", type=float, default=0.05, help="hydraulic conductivity (m/s)")
    dr.add_argument("--porosity", type=float, default=0.4)
    dr.add_argument("--dx", type=float, default=0.01)
    sp = sub.add_parser("sheetpile")
    sp.add_argument("run")
    sp.add_argument("--embed", type=float, default=0.06, help="pile embedment D (m)")
    sp.add_argument("--bed", type=float, default=0.2, help="bed depth (m)")
    sp.add_argument("--length", type=float, default=0.8, help="bed length between its end walls (m)")
    sp.add_argument("--pile", type=float, default=0.02, help="pile thickness (m)")
    sp.add_argument("--gs", type=float, default=2.65)
    sp.add_argument("--porosity", type=float, default=0.4)
    for p in (lv, dr, sp):
        p.add_argument("--json", help="write the numbers to this file")
    a = ap.parse_args()
    out = {"levee": levee, "dry": dry, "sheetpile": sheetpile}[a.case](a)
    text = json.dumps(out, indent=1, default=float)
    print(text if len(text) < 4000 else json.dumps({k: v for k, v in out.items() if not isinstance(v, list)},
                                                      indent=1))
    if a.json:
        Path(a.json).write_text(text)


if __name__ == "__main__":
    main()
