"""Undrained loading of a saturated soil column (mode wcsph_biot, seed 002 section 3.3) and the consolidation
that follows (Terzaghi, eq 55-56).

The column is configs/consolidation.yaml's: soil 0.2 m on the impermeable floor, drained at its top into
free water; E = 1 MPa, nu = 0.3 (constrained modulus M = 1.346 MPa), n = 0.4, the water's default sound
speed with soil, K_f = rho_w c0^2 = 40 M (docs/biot.md, "Storage and c_v").

The load. Stage 1 is the config as it is, kept at its first frame: the K0 start with u_e = u0 cos(pi y /
H) (H = 0.4 m, u0 = 500 Pa) added to the pore water and taken from the soil's effective stress. Stage 2
starts its soil from that frame (`wcsph.soil.start_from`, soil at rest) and its water hydrostatic, so at
t = 0 the skeleton carries u_e less than the weight above it and the water carries nothing extra: the total
vertical stress the column must carry rises suddenly by Delta sigma(y) = u0 cos(pi y / H), with nothing
drained yet. This is Terzaghi's problem loaded by its fundamental mode, so the consolidation after it is
the single term u_e = B Delta sigma(y) exp(-pi^2 Tv), Tv = c_v t / H^2 (eq 56, `exact_excess`).

Undrained response (Skempton 1954, in one-dimensional loading): u / Delta sigma = B = 1 / (1 + n M / K_p)
with K_p the pore fluid's modulus. The model's storage is 1 / K_f per mixture volume (docs/biot.md), i.e.
a pore fluid of modulus K_p = n K_f: B = 1 / (1 + M / K_f) = 1 / 1.025 = 0.976 at K_f = 40 M.

A suddenly applied load sets the column ringing in its undrained quarter-wave mode (period 4 L / c_u,
L = 0.2 m, c_u = sqrt((M + K_f) / (rho_w + (1 - n) rho_s)) = 146 m/s: 5.48 ms) with an amplitude of about
the load itself, decaying at ~20-30 1/s only. The undrained ratio is the mean about which it rings: a least-
squares fit of u / (Delta sigma exp(-pi^2 Tv)) at mid-depth to a constant plus a decaying periodic
signal (two harmonics) over the first 40 ms = 7 periods. The dissipation is read on the one-period mean
of u_e around each Tv, against the one-period mean of the exact solution.

u_e is the water pressure minus that of a twin run without the load and with the same permeability (the
twin relaxes its own start, ~20 Pa at mid-depth; with another k it relaxes at another rate)."""

import numpy as np
import pytest

from taichi_sph.wcsph.consolidation import consolidation_coefficient, exact_excess, water_rows

CONFIG = "configs/consolidation.yaml"
U0, H, SOIL_TOP = 500.0, 0.4, 0.2
E, NU, N0, RHO_S, RHO_W = 1.0e6, 0.3, 0.4, 2650.0, 1000.0
M = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
K_F = 40.0 * M
EVERY = 0.00025
#: quarter-wave period of the undrained column, 4 L / c_u (s)
PERIOD = 4 * SOIL_TOP / np.sqrt((M + K_F) / (RHO_W + (1 - N0) * RHO_S))


def _stage1(run_cli, tmp_path):
    out = tmp_path / "stage1.h5"
    r = run_cli("--config", CONFIG, "--set", "end_time=0.0005", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    return out


def _loaded_and_twin(run_cli, tmp_path, stage1, k, end_time):
    """Stage 2 (loaded at t = 0) and its twin without the load, both at permeability k; frames every 0.25 ms."""
    common = ["--config", CONFIG, "--set", f"end_time={end_time}", "--set", f"output.every={EVERY}",
              "--set", f"wcsph.soil.permeability={k}", "--set", "wcsph.soil.initial_excess_pressure.amplitude=0",
              "--no-progress"]
    loaded, twin = tmp_path / f"loaded_{k}.h5", tmp_path / f"twin_{k}.h5"
    r = run_cli(*common, "--set", f"wcsph.soil.start_from={{run: {stage1}, frame: 0}}", "--out", loaded)
    assert r.returncode == 0, r.stderr
    r = run_cli(*common, "--out", twin)
    assert r.returncode == 0, r.stderr
    t, y, p = water_rows(loaded)
    _, _, p0 = water_rows(twin)
    n = min(len(p), len(p0))
    return t[:n], y[:n], (p[:n] - p0[:n]) / U0


def undrained_ratio(t, y, ue, cv):
    """Mean of u / (Delta sigma exp(-pi^2 Tv)) at mid-depth (the two water rows around y = 0.1 m) about which the
    column rings: fit of m + exp(-lam t) (a1 cos wt + b1 sin wt + a2 cos 2wt + b2 sin 2wt), the period within
    10 % of PERIOD and lam 0-40 1/s scanned, the rest linear least squares. Returns (m, period, lam)."""
    mid = np.abs(y[0] - 0.5 * SOIL_TOP) < 0.006
    r = ue[:, mid].mean(1) / exact_excess(y[:, mid], cv * t[:, None] / H**2, H).mean(1)
    best = None
    for period in np.linspace(0.9, 1.1, 81) * PERIOD:
        w = 2 * np.pi / period
        for lam in np.linspace(0.0, 40.0, 41):
            e = np.exp(-lam * t)
            a = np.array([np.ones_like(t)] + [e * f(h * w * t) for h in (1, 2) for f in (np.cos, np.sin)]).T
            c, *_ = np.linalg.lstsq(a, r, rcond=None)
            res = float(((a @ c - r) ** 2).sum())
            if best is None or res < best[0]:
                best = (res, float(c[0]), period, lam)
    return best[1:]


def dissipation_errors(t, y, ue, cv, tvs):
    """Largest |u_e / u0 - exact| over the soil rows, each side the mean over one ringing period centred on
    the time of Tv; the exact is exact_excess (B = 1). Returns {Tv: error}."""
    soil = y[0] < SOIL_TOP
    out = {}
    for tv in tvs:
        tc = tv * H**2 / cv
        s = np.abs(t - tc) <= 0.5 * PERIOD
        exact = exact_excess(y[s][:, soil], cv * t[s][:, None] / H**2, H).mean(0)
        out[tv] = float(np.abs(ue[s][:, soil].mean(0) - exact).max())
    return out


@pytest.mark.long
def test_undrained_loading_and_consolidation(run_cli, tmp_path):
    """(1) Undrained ratio at mid-depth, k = 5e-5 m/s (c_v = 6.9e-3 m^2/s: Tv = 0.0017 by 40 ms, the load
    is undrained while it rings), t_0+ = the first 40 ms, 7 ringing periods or 28 crossings of the column
    by the undrained wave. Reference: Skempton's B with the model's pore fluid (K_p = n K_f, K_f = 40 M),
    0.976. Measured: 0.965 at dx 0.01 and 0.970 at dx 0.005 since the slip walls carry the soil's velocity
    along their faces with its gradient (docs/biot.md, Terzaghi consolidation); before it 0.967 / 0.971
    (cfl 0.1 instead of 0.25: 0.967); at K_f = 20 M it was 0.944 / 0.948 against B = 0.952. Bounds: the
    acceptance value 0.95, and B - 0.013, set before the walls' change from the shortfall then (0.009)
    plus the spread between dx 0.01 and 0.005 (0.004, as at 20 M; the fit's own scatter between windows
    is 0.0015); the shortfall is now 0.011 and that spread 0.005, so the bound holds with 0.002 to spare.
    (2) Dissipation, k = 5e-3 m/s, Terzaghi's c_v = k M / (rho_w g) (eq 55) = 0.686 m^2/s; the model's own
    c_v is 0.976 of it. Measured, largest |u_e / u0 - exact| over the soil (one-period means): Tv 0.1
    0.0075, Tv 0.2 0.0061 since the slip walls' change (before it 0.021 / 0.028, the model above the exact:
    the layer beside the walls was softer and decayed slower; cfl 0.1: the same to 1e-4; at 20 M the
    smaller B hid part of it: 0.039 / 0.020). Bound 0.015 at both: the measured error plus 0.005 of u0 (the
    ringing left in a one-period mean) and rounding up."""
    stage1 = _stage1(run_cli, tmp_path)

    k_slow = 5e-5
    cv_slow = consolidation_coefficient(k_slow, E, NU)
    t, y, ue = _loaded_and_twin(run_cli, tmp_path, stage1, k_slow, 0.04)
    ratio, period, lam = undrained_ratio(t, y, ue, cv_slow)
    b_skempton = 1.0 / (1.0 + N0 * M / (N0 * K_F))
    assert ratio >= 0.95, (ratio, b_skempton, period, lam)
    assert ratio > b_skempton - 0.013, (ratio, b_skempton, period, lam)
    assert ratio < 1.0, ratio  # the water cannot carry more than the load

    k = 5e-3
    cv = consolidation_coefficient(k, E, NU)
    t, y, ue = _loaded_and_twin(run_cli, tmp_path, stage1, k, 0.125)
    err = dissipation_errors(t, y, ue, cv, (0.1, 0.2))
    assert err[0.1] < 0.015, err
    assert err[0.2] < 0.015, err
