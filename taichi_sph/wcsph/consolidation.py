"""Terzaghi's one-dimensional consolidation (seed 002 section 3.3, eq 55-56, fig 10) measured on run files
of configs/consolidation.yaml: the exact isochrones and the error of a run against them.

The layer of thickness H = 2 x (soil height) is drained at both faces; its lower half is replaced by the
impermeable tank floor (the symmetry plane), so with the sine start u_e / u0 = cos(pi y / H) and
exactly u_e / u0 = cos(pi y / H) exp(-pi^2 Tv), Tv = c_v t / H^2 (eq 56), with Terzaghi's (physical)
c_v = k M / (rho_w g) of eq 55 (`consolidation_coefficient`), M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) the
constrained modulus (plane strain; the seed's eq 55 writes the bulk modulus B^e of its eq 43 there, the
oedometric modulus is the one a laterally confined layer has). The model's own value, with the storage
1 / K_f of the water's EOS (K_f = rho_w c0^2), is `model_consolidation_coefficient` = k / (rho_w g (1 / M
+ 1 / K_f)); the default sound speed keeps K_f >= 40 M, so the two differ by at most 2.5 % (docs/biot.md,
"Storage and c_v").

u_e is the water pressure of the run minus that of the same run without the excess (the model's own
hydrostatic state differs from rho_w g z by about 1 % of the overburden)."""

import numpy as np

G = 9.81
WATER = 0
#: time factors of the isochrones (seed fig 10)
TV = (0.05, 0.1, 0.2, 0.5)


def constrained_modulus(youngs: float, poisson: float) -> float:
    """M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) (Pa), the oedometric modulus (plane strain: lambda + 2 G)."""
    return youngs * (1 - poisson) / ((1 + poisson) * (1 - 2 * poisson))


def consolidation_coefficient(k: float, youngs: float, poisson: float, rho_w: float = 1000.0,
                              g: float = G) -> float:
    """Terzaghi's c_v = k M / (rho_w g) (m^2/s) of eq 55, M the constrained modulus: incompressible water."""
    return k * constrained_modulus(youngs, poisson) / (rho_w * g)


def model_consolidation_coefficient(k: float, youngs: float, poisson: float, sound_speed: float,
                                    rho_w: float = 1000.0, g: float = G) -> float:
    """The model's c_v = k / (rho_w g (1 / M + 1 / K_f)) (m^2/s), K_f = rho_w c0^2 the water's EOS modulus
    (its storage per mixture volume is 1 / K_f, docs/biot.md)."""
    return k / (rho_w * g * (1 / constrained_modulus(youngs, poisson) + 1 / (rho_w * sound_speed**2)))


def exact_excess(y, tv: float, half: float) -> np.ndarray:
    """u_e / u0 = cos(pi y / H) exp(-pi^2 Tv), y above the floor (the layer's middle), H = half."""
    return np.cos(np.pi * np.asarray(y) / half) * np.exp(-np.pi**2 * tv)


def water_rows(path):
    """Water pressure averaged over each starting lattice row, per frame: (times, row heights, pressures)."""
    from ..io.hdf5 import RunFile

    with RunFile(path) as rf:
        water = rf.kind == WATER
        y0 = rf.field("position", 0)[water][:, -1]
        row = np.round((y0 - 0.5 * rf.dx) / rf.dx).astype(int)
        rows = range(row.max() + 1)
        times, ys, ps = [], [], []
        for k in range(rf.n_frames):
            f = rf.frame(k)
            y = f["position"][water][:, -1]
            p = f["pressure"][water]
            times.append(f["time"])
            ys.append(np.array([y[row == r].mean() for r in rows]))
            ps.append(np.array([p[row == r].mean() for r in rows]))
    return np.array(times), np.array(ys), np.array(ps)


def isochrone_errors(run, base, u0: float, half: float, soil_top: float, cv: float, tvs=TV) -> dict:
    """Largest |u_e / u0 - exact| over the soil rows (y < soil_top) at the frame nearest each Tv, for the
    run file `run` and its twin without the excess `base`. Returns {Tv: (error, u_e / u0, exact)}."""
    t, y, p = water_rows(run)
    _, _, p0 = water_rows(base)
    out = {}
    for tv in tvs:
        i = int(np.argmin(np.abs(t - tv * half**2 / cv)))
        soil = y[i] < soil_top
        ue = (p[i] - p0[i])[soil] / u0
        exact = exact_excess(y[i][soil], cv * t[i] / half**2, half)
        out[tv] = (float(np.abs(ue - exact).max()), ue, exact)
    return out
