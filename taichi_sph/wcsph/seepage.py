"""Upward seepage through a soil column and the critical hydraulic gradient (seed 002 section 2.5),
measured on run files of configs/upward_seepage.yaml.

Critical gradient: the upward seepage force i gamma_w per unit volume balances the buoyant weight
gamma' = gamma_sat - gamma_w = (1 - n) (rho_s - rho_w) g when

    i_c = gamma' / gamma_w = (1 - n) (Gs - 1) = (Gs - 1) / (1 + e),   Gs = rho_s / rho_w, e = n / (1 - n).

In steady upward seepage at gradient i < i_c the vertical effective stress at depth z below the column's
top is sigma'_v = (gamma' - i gamma_w) z; at i >= i_c it vanishes and the column lifts (heave).

Measured on one frame, over the soil particles of the column (a box given by the caller; the rigid base
below it excluded): the gradient from the pore pressure p (gauge) at the soil particles, the slope of a
least-squares line p(y) in the column's interior (a kernel's width, 2 dx, off its top and bottom, where the
support is truncated), i = -dp/dy / (rho_w g) - 1 (the head h = p / (rho_w g) + y falls by i per metre
upward); the effective-stress ratio, the slope of sigma'_v against depth over gamma' over the same rows,
1 - i / i_c in theory; the heave, the mean rise of the column's top row of soil since the start.
"""

import numpy as np

G = 9.81
SOIL = 2


def critical_gradient(porosity: float, grain_density: float, rho_w: float = 1000.0) -> float:
    """i_c = (1 - n) (Gs - 1) = (Gs - 1) / (1 + e)."""
    return (1.0 - porosity) * (grain_density / rho_w - 1.0)


def column_state(path, box, frame: int = -1, rho_w: float = 1000.0, g: float = G) -> dict:
    """Gradient, effective-stress ratio and heave of the soil column inside `box` ([[x0, y0], [x1, y1]] at
    the start; the column's particles are chosen on frame 0) at `frame`. Returns a dict with time,
    gradient, stress_ratio (slope of sigma'_v with depth over gamma'), heave (m), gamma_buoyant (Pa/m)."""
    from ..io.hdf5 import RunFile

    lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
    with RunFile(path) as rf:
        dx = rf.dx
        x0 = rf.field("position", 0)
        col = (rf.kind == SOIL) & np.all((x0 >= lo) & (x0 <= hi), axis=1)
        cfg = rf.config_yaml
        f = rf.frame(frame if frame >= 0 else rf.n_frames + frame)
        y = f["position"][col][:, -1]
        p = f["pressure"][col]
        sv = f["effective_stress"][col][:, -1, -1]
        rho_s = f["density"][col]
    import yaml

    soil = (yaml.safe_load(cfg).get("wcsph") or {}).get("soil") or {}
    grain = float(soil.get("grain_density", 2650.0))
    n0 = float(soil.get("porosity", 0.4))
    y_start = x0[col][:, -1]
    top0 = y_start.max()
    inner = (y_start > y_start.min() + 2.0 * dx - 1e-9) & (y_start < top0 - 2.0 * dx + 1e-9)
    dpdy = np.polyfit(y[inner], p[inner], 1)[0]
    gradient = -dpdy / (rho_w * g) - 1.0
    n = 1.0 - float(np.mean(rho_s)) / grain  # the column's porosity now (it loosens as it heaves)
    gamma_b = (1.0 - n0) * (grain - rho_w) * g
    depth = top0 - y_start
    slope = np.polyfit(depth[inner], sv[inner], 1)[0]
    top_row = y_start > top0 - 0.5 * dx
    heave = float(np.mean(y[top_row] - y_start[top_row]))
    return {"time": float(f["time"]), "gradient": float(gradient), "stress_ratio": float(slope / gamma_b),
            "heave": heave, "gamma_buoyant": gamma_b, "porosity": n0, "porosity_now": n,
            "grain_density": grain}


def averaged_state(path, box, since: float, rho_w: float = 1000.0, g: float = G) -> dict:
    """`column_state` averaged over the frames at t >= since (the weakly compressible water carries a
    slowly damped acoustic oscillation of the reservoir, +-0.05 in i): mean gradient and stress ratio,
    heave at the last frame, and the gradient at which sigma'_v would vanish on the line sigma'_v / (gamma' z)
    = 1 - i / i_c through the measured point, i_zero = i / (1 - stress ratio)."""
    from ..io.hdf5 import RunFile

    with RunFile(path) as rf:
        times = [float(rf.frame(k)["time"]) for k in range(rf.n_frames)]
    states = [column_state(path, box, k, rho_w, g) for k, t in enumerate(times) if t >= since - 1e-9]
    if not states:
        raise ValueError(f"{path}: no frame at t >= {since:g} s")
    i_mean = float(np.mean([s["gradient"] for s in states]))
    ratio = float(np.mean([s["stress_ratio"] for s in states]))
    last = states[-1]
    return {"time": last["time"], "frames": len(states), "gradient": i_mean,
            "gradient_spread": float(np.std([s["gradient"] for s in states])), "stress_ratio": ratio,
            "heave": last["heave"], "i_zero": i_mean / (1.0 - ratio) if ratio < 1.0 else float("inf"),
            "i_c": critical_gradient(last["porosity"], last["grain_density"], rho_w)}
