"""Numbers and pictures of the seepage-failure cases (docs/levee.md, docs/sheetpile.md) from their run files.

    python tools/seepage_failure.py levee STAGE1.h5 STAGE2.h5 [--toe 2.26] [--dx DX]
    python tools/seepage_failure.py dry RUN.h5 [--entry 1.26] [--toe 2.26] [--k 0.03] [--porosity 0.4] [--dx DX]
    python tools/seepage_failure.py sheetpile RUN.h5 [--embed 0.06] [--bed 0.2] [--length 0.54] [--at 0.12]
    python tools/seepage_failure.py figure RUN.h5 --times 0,20,40 --out PNG [--xlim 1.1,2.76] [--cols 1]

levee: stage 1's largest displacement and plastic strain; stage 2's first yielded particle (plastic
strain > 1e-2) and its distance from the landside toe, the highest yielded point over time and how far it
ever falls back before the overflow, the first time water stands on the crest (probe `overflow`) and
the crest's fall (probe `crest`), the river level (probe `river`).
dry: the wetting front's foot (along the floor) against the Boussinesq solution
x_f = 1.62 sqrt(k integral(H dt) / S) for the river level H(t) read by probe `river`, with the
drainable porosity S = 1 (the model's: its water particles fill the pores at full volume) and S = n; the
comparison is on the advance after a reference time, so the entry's place on the sloping face drops out;
the advance's exponent in time; the phreatic line's shape.
sheetpile: the head difference at heave (the mean surface over the prism's width D up by 1 mm, probe
`heave`), the mean excess head on the prism's base from the run's own pressures just before heave
(probes `p_base_*`), and Terzaghi's critical head difference from that head and from the flow net.
figure: soil coloured by plastic strain (drawn over the water), water by pressure, the phreatic line (per
soil column, the highest pore water) dashed; one panel per time.
Each prints its numbers and, with --json FILE, writes them.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from taichi_sph.io.hdf5 import RunFile  # noqa: E402
from taichi_sph.wcsph import failure  # noqa: E402
from taichi_sph.wcsph.dupuit import boussinesq_front_coefficient  # noqa: E402
from taichi_sph.wcsph.flownet import critical_head_difference, prism_ratio  # noqa: E402


def _probe(rf: RunFile, name: str):
    t, v = rf.probes()[name]
    return np.asarray(t, float), np.asarray(v, float)


def levee(a) -> dict:
    _spacing(a, a.stage2)
    with RunFile(a.stage1) as rf:
        soil = np.asarray(rf.kind) == failure.SOIL
        x0 = np.asarray(rf.field("position", 0), float)[soil]
        x1 = np.asarray(rf.field("position", rf.n_frames - 1), float)[soil]
        eps1 = np.asarray(rf.field("plastic_strain", rf.n_frames - 1), float)[soil]
    out = {"stage1_max_disp_mm": 1e3 * float(np.linalg.norm(x1 - x0, axis=1).max()),
           "stage1_max_plastic_strain": float(eps1.max())}
    seq = failure.yield_sequence(a.stage2, 1e-2)
    first = seq["first"]
    toe = np.array([a.toe, 0.0])
    if first:
        pts = np.asarray(first["x0"])
        d = np.linalg.norm(pts - toe, axis=1)
        out["first_yield_time"] = first["time"]
        out["first_yield_points"] = pts.tolist()
        out["first_yield_most_strained"] = first["x0_max"]
        d_max = np.linalg.norm(np.asarray(first["x0_max"]) - toe)
        out["first_yield_dist_to_landside_toe_dx"] = float(d_max / a.dx)
        out["first_yield_farthest_from_toe_dx"] = float(d.max() / a.dx)
    t = np.asarray(seq["time"])
    top = np.asarray(seq["top_z"])
    with RunFile(a.stage2) as rf:
        names = rf.probes().keys()
        over = _probe(rf, "overflow") if "overflow" in names else None
        crest = _probe(rf, "crest") if "crest" in names else None
        river = _probe(rf, "river") if "river" in names else None
    t_over = math.inf
    if over is not None:
        wet = np.flatnonzero(over[1] > 0.0)
        t_over = float(over[0][wet[0]]) if wet.size else math.inf
        out["overflow_time"] = t_over if wet.size else None
        out["overflow_depth_max"] = float(over[1].max())
    seen = np.isfinite(top)
    out["yield_top"] = [[float(ti), float(zi), float(xi)] for ti, zi, xi in
                        zip(t[seen], top[seen], np.asarray(seq["top_x"])[seen])]
    climb = seen & (t <= t_over)
    if climb.any():  # monotone within 2 dx: the running maximum exceeds no later reading by more than 2 dx
        run_max = np.maximum.accumulate(top[climb])
        out["yield_top_largest_fall_back_dx"] = float(np.max(run_max - top[climb]) / a.dx)
        out["yield_top_before_overflow"] = float(top[climb].max())
    if crest is not None:
        tc, zc = crest
        out["crest_start"] = float(zc[0])
        out["crest_min"] = float(zc.min())
        out["crest_fall_pct"] = 100.0 * (zc[0] - zc.min()) / zc[0]
        below = np.flatnonzero(zc < 0.8 * zc[0])
        out["crest_fall_20pct_time"] = float(tc[below[0]]) if below.size else None
    if river is not None:
        tr, zr = river
        out["river_level"] = [[float(x), float(y)] for x, y in zip(tr[:: max(1, len(tr) // 40)],
                                                                     zr[:: max(1, len(tr) // 40)])]
        out["river_max"] = float(zr.max())
    out["stage2_end_time"] = float(t[-1])
    return out


def _spacing(a, path) -> None:
    """--dx, or the run file's own spacing: a coarse run read at a finer dx misses its bottom row."""
    if a.dx is None:
        with RunFile(path) as rf:
            a.dx = float(rf.dx)


def _soil(a, path) -> None:
    """--k and --porosity, or the run's own soil (wcsph.soil.permeability, .porosity): a sweep over k reads
    each run against its own conductivity."""
    if a.k is None or a.porosity is None:
        with RunFile(path) as rf:
            soil = (yaml.safe_load(rf.config_yaml) or {}).get("wcsph", {}).get("soil", {})
        a.k = float(soil["permeability"]) if a.k is None else a.k
        a.porosity = float(soil["porosity"]) if a.porosity is None else a.porosity


def dry(a) -> dict:
    _spacing(a, a.run)
    _soil(a, a.run)
    if a.t_ref is None:
        a.t_ref = 0.06 / a.k
    wf = failure.wetting_front(a.run, a.dx, a.entry)
    t = np.asarray(wf["time"])
    front = np.asarray(wf["front"])
    with RunFile(a.run) as rf:
        tr, hr = _probe(rf, "river")
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (hr[1:] + hr[:-1]) * np.diff(tr))])  # integral of H dt
    integral = np.interp(t, tr, cum)
    eta = boussinesq_front_coefficient()
    ok = np.isfinite(front) & (t >= a.t_ref) & (front < a.toe - 2 * a.dx)
    out = {"eta_f": eta, "t_ref": a.t_ref, "k": a.k, "porosity": a.porosity, "rows": []}
    if ok.sum() < 2:
        return out
    k0 = int(np.flatnonzero(ok)[0])
    adv = front[ok] - front[k0]
    for s_name, s in (("S1", 1.0), ("Sn", a.porosity)):
        ref = eta * np.sqrt(a.k * integral / s)
        out[f"advance_ref_{s_name}"] = (ref[ok] - ref[k0]).tolist()
    out["rows"] = [[float(ti), float(fi), float(ai), float(r1), float(rn)] for ti, fi, ai, r1, rn in
                   zip(t[ok], front[ok], adv, out["advance_ref_S1"], out["advance_ref_Sn"])]
    late = adv > 2 * a.dx  # the advance resolved by more than two particles
    for s_name in ("S1", "Sn"):
        ref = np.asarray(out[f"advance_ref_{s_name}"])
        if late.any():
            out[f"largest_error_pct_{s_name}"] = float(100 * np.max(np.abs(adv[late] / ref[late] - 1.0)))
            out[f"final_error_pct_{s_name}"] = float(100 * (adv[-1] / ref[-1] - 1.0))
    if ok.sum() >= 4:  # x_f = a + b t^p fitted over t >= t_ref: p below 1 is an advance slower than linear
        best = None
        for p in np.linspace(0.2, 1.5, 131):
            A = np.c_[np.ones(ok.sum()), t[ok] ** p]
            coef, res, *_ = np.linalg.lstsq(A, front[ok], rcond=None)
            r = float(np.sum((A @ coef - front[ok]) ** 2))
            if best is None or r < best[0]:
                best = (r, float(p))
        out["advance_exponent"] = best[1]
    cols = np.asarray(wf["columns"])
    shapes = []
    for ti in a.shape_times:
        i = int(np.argmin(np.abs(t - ti)))
        h = np.asarray(wf["table"][i])
        wet = np.flatnonzero(h > 0)
        if wet.size < 3:
            continue
        xs, hs = cols[wet], h[wet]
        top = int(np.argmax(hs))  # the line from its highest point (where the river meets the slope) on
        xs, hs = xs[top:], hs[top:]
        if xs.size < 3:
            continue
        # convex downward: the line lies below the chord from its entry (highest) to its front
        chord = np.interp(xs, [xs[0], xs[-1]], [hs[0], hs[-1]])
        shapes.append({"time": float(t[i]), "x": xs.tolist(), "h": hs.tolist(),
                       "below_chord_share": float(np.mean(hs[1:-1] <= chord[1:-1] + 1e-9)),
                       "mean_sag_mm": float(1e3 * np.mean(chord[1:-1] - hs[1:-1]))})
    out["shapes"] = shapes
    return out


def sheetpile(a) -> dict:
    with RunFile(a.run) as rf:
        th, heave = _probe(rf, "heave")
        tu, hu = _probe(rf, "h_upstream")
        td, hd = _probe(rf, "h_downstream")
        names = sorted(n for n in rf.probes() if n.startswith("p_base"))
    lift = heave - heave[0]
    up = np.flatnonzero(lift > 1e-3)
    dh = np.interp(th, tu, hu) - np.interp(th, td, hd)
    out = {"heave_time": float(th[up[0]]) if up.size else None, "dH_max": float(dh.max())}
    step = max(1, len(th) // 40)
    out["dH_series"] = [[float(x), float(y), float(z)]
                        for x, y, z in zip(th[::step], dh[::step], lift[::step])]
    base = a.bed - a.embed
    tb, ha = failure.excess_head_on_base(a.run, names, base, "h_downstream")
    ratio = np.interp(th, tb, ha) / np.where(np.abs(dh) > 1e-9, dh, np.nan)
    if up.size:
        k = max(up[0] - 1, 0)  # the sample just before heave
        out["dH_at_heave"] = float(dh[up[0]])
        out["h_a_before_heave"] = float(np.interp(th[k], tb, ha))
        out["h_a_ratio_model"] = float(ratio[k])
        out["dH_c_model_field"] = critical_head_difference(float(ratio[k]), a.embed, a.gs, a.porosity)
    r_net = prism_ratio(a.length, a.bed, a.embed, a.pile, 0.0025, a.at)
    out["h_a_ratio_flownet"] = r_net
    out["dH_c_flownet"] = critical_head_difference(r_net, a.embed, a.gs, a.porosity)
    if up.size:
        out["heave_vs_model_field_pct"] = 100 * (out["dH_at_heave"] / out["dH_c_model_field"] - 1)
        out["heave_vs_flownet_pct"] = 100 * (out["dH_at_heave"] / out["dH_c_flownet"] - 1)
    return out


def figure(a) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    times = [float(s) for s in a.times.split(",")]
    with RunFile(a.run) as rf:
        kind = np.asarray(rf.kind)
        dx = rf.dx
        tt = np.asarray(rf.times, float)
        xlim = [float(v) for v in a.xlim.split(",")] if a.xlim else None
        rows = -(-len(times) // a.cols)
        fig, axes = plt.subplots(rows, a.cols, figsize=(a.width, a.panel * rows), squeeze=False)
        for ax in axes.flat[len(times):]:
            ax.set_visible(False)
        for ax, ti in zip(axes.flat, times):
            i = int(np.argmin(np.abs(tt - ti)))
            pos = np.asarray(rf.field("position", i), float)
            act = np.asarray(rf.field("active", i), bool)
            w = (kind == failure.WATER) & act
            s = kind == failure.SOIL
            eps = np.asarray(rf.field("plastic_strain", i), float)[s]
            pw = np.asarray(rf.field("pressure", i), float)[w]
            ms = (72 * dx * a.width / a.cols / (xlim[1] - xlim[0] if xlim else 1.0)) ** 2 * 0.5
            wa = ax.scatter(pos[w, 0], pos[w, -1], s=0.35 * ms, c=pw / 1e3, cmap="Blues", vmin=0, vmax=a.pmax,
                            linewidths=0)
            so = ax.scatter(pos[s, 0], pos[s, -1], s=ms, marker="s", c=np.log10(np.maximum(eps, 1e-4)),
                            cmap="YlOrBr", vmin=-4, vmax=0, linewidths=0, alpha=0.75)
            x, top, h = failure.phreatic_line(pos, kind, act, dx)
            wet = h > 0
            ax.plot(x[wet], h[wet], "c--", lw=1.2)
            ax.set_aspect("equal")
            ax.set_ylim(0, a.ytop)
            if xlim:
                ax.set_xlim(*xlim)
            ax.set_title(f"t = {tt[i]:.1f} s", fontsize=9, loc="left")
            ax.tick_params(labelsize=7)
        fig.subplots_adjust(left=0.06, right=0.8, top=0.95, bottom=0.08, hspace=0.55)
        for cx, art, label in ((0.83, so, "log10 plastic strain"), (0.92, wa, "water pressure (kPa)")):
            cb = fig.colorbar(art, cax=fig.add_axes([cx, 0.15, 0.015, 0.7]))
            cb.set_label(label, fontsize=8)
            cb.ax.tick_params(labelsize=7)
        fig.savefig(a.out, dpi=a.dpi)
    return {"figure": a.out, "times": times}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="case", required=True)
    lv = sub.add_parser("levee")
    lv.add_argument("stage1")
    lv.add_argument("stage2")
    lv.add_argument("--toe", type=float, default=2.26, help="x of the landside toe (m)")
    lv.add_argument("--dx", type=float, default=None, help="particle spacing (m); default: the run file's")
    dr = sub.add_parser("dry")
    dr.add_argument("run")
    dr.add_argument("--entry", type=float, default=1.26, help="riverside toe x (m)")
    dr.add_argument("--toe", type=float, default=2.26, help="x of the landside toe (m)")
    dr.add_argument("--k", type=float, default=None, help="hydraulic conductivity (m/s); default: the run's")
    dr.add_argument("--porosity", type=float, default=None, help="the soil's porosity n; default: the run's")
    dr.add_argument("--t-ref", dest="t_ref", type=float, default=None,
                    help="the advance's start time (s); default 0.06 m / k (2 s at k 3 cm/s): the seepage's time "
                         "scale is 1 / k, so runs at other k start at the same stage")
    dr.add_argument("--shape-times", dest="shape_times", type=lambda s: [float(v) for v in s.split(",")],
                    default=[5.0, 10.0, 20.0])
    dr.add_argument("--dx", type=float, default=None, help="particle spacing (m); default: the run file's")
    sp = sub.add_parser("sheetpile")
    sp.add_argument("run")
    sp.add_argument("--embed", type=float, default=0.06, help="pile embedment D (m)")
    sp.add_argument("--bed", type=float, default=0.2, help="bed depth (m)")
    sp.add_argument("--length", type=float, default=0.54, help="bed length between its end walls (m)")
    sp.add_argument("--at", type=float, default=0.12, help="the pile's upstream face from the bed's end (m)")
    sp.add_argument("--pile", type=float, default=0.03, help="pile thickness (m)")
    sp.add_argument("--gs", type=float, default=2.65)
    sp.add_argument("--porosity", type=float, default=0.4)
    fg = sub.add_parser("figure")
    fg.add_argument("run")
    fg.add_argument("--times", required=True, help="comma-separated times (s); the nearest frames are drawn")
    fg.add_argument("--out", required=True, help="PNG file")
    fg.add_argument("--xlim", help="x range lo,hi (m)")
    fg.add_argument("--ytop", type=float, default=0.2, help="top of the panels (m)")
    fg.add_argument("--pmax", type=float, default=1.5, help="top of the water pressure scale (kPa)")
    fg.add_argument("--width", type=float, default=8.0, help="figure width (inches)")
    fg.add_argument("--panel", type=float, default=1.5, help="height of one panel (inches)")
    fg.add_argument("--cols", type=int, default=1, help="panels per row")
    fg.add_argument("--dpi", type=int, default=80)
    for p in (lv, dr, sp, fg):
        p.add_argument("--json", help="write the numbers to this file")
    a = ap.parse_args()
    out = {"levee": levee, "dry": dry, "sheetpile": sheetpile, "figure": figure}[a.case](a)
    text = json.dumps(out, indent=1, default=float)
    short = {k: v for k, v in out.items() if not isinstance(v, list)}
    print(text if len(text) < 4000 else json.dumps(short, indent=1, default=float))
    if a.json:
        Path(a.json).write_text(text)


if __name__ == "__main__":
    main()
