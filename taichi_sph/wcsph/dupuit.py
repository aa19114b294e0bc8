"""Steady seepage through a rigid rectangular levee (configs/levee_seepage.yaml) measured against Dupuit's
discharge q = k (h1^2 - h2^2) / (2 L) per unit width, exact for a rectangular dam with vertical faces
(Charny 1951) even with a seepage face above the tailwater.

The model's discharge is the slope of the downstream basin's water volume (a `water_volume` probe) over
a time window after the start-up; Dupuit's is averaged over the frames of the same window, with h1 the
reservoir level (the 99.5th percentile of the water's height in the reservoir, plus half a particle) and
h2 the basin's water volume over its width (the reservoir falls slowly, so the state is quasi-steady)."""

from functools import lru_cache

import numpy as np

WATER = 0


def dupuit_discharge(k: float, h1: float, h2: float, length: float) -> float:
    """q = k (h1^2 - h2^2) / (2 L) (m^2/s), k the hydraulic conductivity (m/s)."""
    return k * (h1**2 - h2**2) / (2 * length)


def discharge_ratio(path, k: float, length: float, t_from: float, reservoir=(0.1, 0.5), basin_from: float = 0.76,
                    basin_width: float = 0.24, probe: str = "downstream") -> dict:
    """q_model / q_Dupuit over t >= t_from of a run file: {"ratio", "q", "q_dupuit", "h1", "h2"}."""
    from ..io.hdf5 import RunFile

    heads = []
    with RunFile(path) as rf:
        t, vol = rf.probes()[probe]
        for i in range(rf.n_frames):
            f = rf.frame(i)
            if f["time"] < t_from - 1e-9:
                continue
            x = f["position"][(rf.kind == WATER) & f["active"]]
            up = (x[:, 0] > reservoir[0]) & (x[:, 0] < reservoir[1])
            h1 = np.percentile(x[up, -1], 99.5) + 0.5 * rf.dx
            h2 = (x[:, 0] > basin_from).sum() * rf.dx ** (x.shape[1]) / basin_width
            heads.append((h1, h2, dupuit_discharge(k, h1, h2, length)))
    sel = t >= t_from - 1e-9
    if sel.sum() < 2 or not heads:
        raise ValueError(f"{path}: fewer than two probe values after t = {t_from} s")
    q = float(np.polyfit(t[sel], vol[sel], 1)[0])
    heads = np.array(heads)
    qd = float(heads[:, 2].mean())
    return {"ratio": q / qd, "q": q, "q_dupuit": qd, "h1": float(heads[:, 0].mean()), "h2": float(heads[:, 1].mean())}


def section_discharge(path, sections, t_from: float, t_to: float = float("inf")) -> np.ndarray:
    """Mean discharge (m^2/s) through vertical sections of a run file over t_from <= t <= t_to: for each
    section x_s, the water particles within dx / 2 of it carry sum V_i (x_i(t + dt_f) - x_i(t)) / dt_f / dx,
    from the displacement between consecutive frames (dt_f apart; particles keep their place in the frame
    arrays) rather than the frame velocity, which inside the soil is v + dt a / 2 without the drag and
    reads a few % high. In steady seepage through a rigid dam every section carries the same discharge."""
    from ..io.hdf5 import RunFile

    sections = np.asarray(sections, float)
    total = np.zeros(len(sections))
    n = 0
    with RunFile(path) as rf:
        dx, d = rf.dx, rf.dim
        rho_w = float(rf.attrs.get("rho_w", 1000.0))
        times = [rf.frame(i)["time"] for i in range(rf.n_frames)]
        use = [i for i in range(rf.n_frames - 1) if times[i] >= t_from - 1e-9 and times[i + 1] <= t_to + 1e-9]
        for i in use:
            f, g = rf.frame(i), rf.frame(i + 1)
            w = (rf.kind == WATER) & f["active"] & g["active"]
            x = f["position"]
            vol = dx**d * rho_w / f["density"]  # m / rho, the particle's mass being rho_w dx^d
            disp = (g["position"][:, 0] - x[:, 0]) / (g["time"] - f["time"])
            for k, xs in enumerate(sections):
                s = w & (np.abs(x[:, 0] - xs) < dx / 2)
                total[k] += (vol[s] * disp[s]).sum() / dx ** (d - 1)
            n += 1
    if n == 0:
        raise ValueError(f"{path}: no pair of frames within {t_from} - {t_to} s")
    return total / n


@lru_cache(maxsize=4)
def boussinesq_front_coefficient(cells: int = 800) -> float:
    """eta_f of the wetting front of a dry aquifer (or levee) against a river held at level H from t = 0:
    the Boussinesq equation n h_t = k (h h_x)_x with h(0, t) = H and h(x, 0) = 0 has the similarity
    solution h = H f(x / sqrt(k H t / n)), whose front stands at x_f = eta_f sqrt(k H t / n) (the advance
    is slower than linear in time). Solved here by explicit finite volumes in the dimensionless form
    h_t = (h h_x)_x on [0, 4] to t = 1 with `cells` cells; the front is where h falls below 1e-4.
    800 cells give 1.620, 400 give 1.630 (Polubarinova-Kochina's value is 1.62)."""
    dx = 4.0 / cells
    h = np.zeros(cells + 1)
    h[0] = 1.0
    dt = 0.2 * dx * dx
    steps = int(np.ceil(1.0 / dt))
    for _ in range(steps):
        hm = 0.5 * (h[1:] + h[:-1])
        q = -hm * (h[1:] - h[:-1]) / dx
        h[1:-1] -= dt * (q[1:] - q[:-1]) / dx
    return float(np.argmax(h < 1e-4) * dx / np.sqrt(steps * dt))


def boussinesq_front(k: float, porosity: float, head: float, t) -> np.ndarray:
    """Wetting-front distance x_f = eta_f sqrt(k H t / n) (m) from the river's entry face at times t (s);
    k the hydraulic conductivity (m/s), n the drainable porosity, H the river level above the floor (m)."""
    return boussinesq_front_coefficient() * np.sqrt(k * head * np.asarray(t, float) / porosity)
