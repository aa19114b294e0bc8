"""Final deposit of a granular column collapse (2D, mode wcsph_biot) and the true-2D experiments it is
compared with (docs/biot.md, "Granular column collapse").

The column of width d0 and height h0 (aspect ratio a = h0 / d0) stands against the back wall at x = 0 and
spreads along +x. The final height h is the top of the deposit: the highest soil particle plus dx / 2.
The run-out d is where the deposit ends. Its front thins into a sheet one particle thick and then into
single particles spaced apart, and that sheet lengthens as dx shrinks, so the farthest particle is no
measure. An experiment's deposit cannot be thinner than one grain, so the deposit is taken to end where its
thickness (soil volume per unit length, the particles' volume dx^2 each, over windows of width w = max(0.2
d0, 2 dx) from the back wall on) first falls below one grain diameter (`grain`, the rods' 1.5 mm),
interpolated linearly between the centres of the last window above and the first below.
"""

from __future__ import annotations

import numpy as np

SOIL = 2


def experiment_fit(a: float, table) -> dict:
    """Final run-out d / d0 and height h / h0 at aspect ratio a = h0 / d0 from power-law fits to experiments,
    `table` a CSV file (tests/data/nguyen_2015_true2d_collapse.csv: the true-2D aluminium-rod columns of
    Nguyen et al. 2015) with rows quantity, coefficient, exponent, a_min, a_max: runout_excess (d - d0) / d0
    = coefficient a^exponent and height_ratio h0 / h = coefficient a^exponent, each on a_min <= a <= a_max.
    NaN where no row covers a; where two rows of a quantity cover it (their common end), the first."""
    from pathlib import Path

    rows = [line.split(",") for line in Path(table).read_text().splitlines()
            if line.strip() and not line.startswith("#") and not line.startswith("quantity")]
    out = {"runout": float("nan"), "height": float("nan")}
    for name, coef, expo, lo, hi in rows:
        if float(lo) <= a <= float(hi):
            value = float(coef) * a ** float(expo)
            key, v = ("runout", 1.0 + value) if name == "runout_excess" else ("height", 1.0 / value)
            if out[key] != out[key]:  # still NaN
                out[key] = v
    return out


def deposit(x: np.ndarray, dx: float, d0: float, grain: float = 1.5e-3) -> dict:
    """Run-out d (m, from x = 0) and final height h (m) of the deposit of soil particles at positions x (n x
    2), spacing dx, column width d0; also the windows' thickness and edges (m)."""
    w = max(0.2 * d0, 2.0 * dx)
    edges = np.arange(0.0, x[:, 0].max() + 2.0 * w, w)
    count, _ = np.histogram(x[:, 0], edges)
    thickness = count * dx * dx / w
    k = int(np.flatnonzero(thickness < grain)[0])
    centre = edges[:-1] + 0.5 * w
    if k == 0:
        runout = 0.0
    else:  # where the thickness crosses one grain, linearly between the window centres
        runout = centre[k - 1] + w * (thickness[k - 1] - grain) / (thickness[k - 1] - thickness[k])
    return {"runout": float(runout), "height": float(x[:, 1].max() + 0.5 * dx), "thickness": thickness,
            "edges": edges}


def final_deposit(path, frame: int = -1, grain: float = 1.5e-3) -> dict:
    """deposit() of the soil in one frame of a run file, with the column's d0, h0 and a = h0 / d0 read from
    its first frame and the soil's median speed (m/s) in that frame."""
    from ..io.hdf5 import RunFile

    with RunFile(path) as rf:
        soil = rf.kind == SOIL
        i = frame if frame >= 0 else rf.n_frames + frame
        x0 = rf.field("position", 0)[soil]
        d0, h0 = float(x0[:, 0].max() + 0.5 * rf.dx), float(x0[:, 1].max() + 0.5 * rf.dx)
        f = rf.frame(i)
        out = deposit(f["position"][soil], rf.dx, d0, grain)
        out.update(d0=d0, h0=h0, a=h0 / d0)
        out["median_speed"] = float(np.median(np.linalg.norm(f["velocity"][soil], axis=1)))
        out["time"] = float(rf.times[i])
    return out
