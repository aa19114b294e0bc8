"""The fast subset of the validation suite (tools/validate.py) and of the stress matrix (tools/stress.py),
with tolerances from their measured numbers (docs/validation.md, docs/stability.md)."""

import importlib.util
import math
import sys

import numpy as np
import pytest

from .conftest import ROOT


def _tool(name):
    spec = importlib.util.spec_from_file_location(f"_tool_{name}", ROOT / "tools" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


validate = _tool("validate")
stress = _tool("stress")


def test_observed_order_of_a_known_series():
    """e = 3 dx^2 gives order 2 between every pair and in the fit; a NaN error is skipped."""
    dx = np.array([0.04, 0.02, 0.01])
    pair, fit = validate.observed_orders(dx, 3 * dx**2)
    assert np.allclose(pair, 2.0) and math.isclose(fit, 2.0)
    pair, fit = validate.observed_orders([0.04, 0.02, 0.01], [1e-2, float("nan"), 2.5e-3])
    assert math.isnan(pair[0]) and math.isclose(fit, 1.0)


def test_every_case_has_runs_of_three_resolutions_or_is_pending():
    for c in validate.CASES.values():
        if c.pending:
            continue
        runs, _ = c.build("small")
        for v in {r.variant for r in runs}:
            assert len({r.dx for r in runs if r.variant == v}) >= 3, (c.name, v)
    names = set(validate.CASES)
    assert {"hydrostatic", "dambreak", "darcy_column", "permeameter", "freefall"} <= names
    assert {"terzaghi", "dupuit", "critical_gradient", "taylor_green", "channel_startup", "granular_collapse"} <= names
    assert not any(c.pending for c in validate.CASES.values())


def test_a_case_run_again_replaces_only_its_own_results(tmp_path):
    """Running some cases keeps the others' rows from the JSON beside the report (with the setting and
    machine an older file kept once, at its top); the report's total time is the sum of the cases'."""
    old = {"setting": "small", "machine": "m1", "seconds": 99.0, "cases": {
        "terzaghi": {"rows": [{"process_seconds": 10.0, "twin process s": 5.0}], "variants": {}},
        "hydrostatic": {"rows": [{"process_seconds": 7.0}], "variants": {}}}}
    path = tmp_path / "validation.json"
    path.write_text(validate.json.dumps(old))
    kept = validate.load_results(path)
    assert kept["terzaghi"]["setting"] == "small" and kept["hydrostatic"]["machine"] == "m1"
    new = {"terzaghi": {"rows": [], "variants": {}, "setting": "full", "machine": "m2", "seconds": 60.0}}
    merged = validate.merge_results(kept, new)
    assert list(merged) == ["hydrostatic", "terzaghi"]  # registry order
    assert merged["terzaghi"]["setting"] == "full" and merged["hydrostatic"]["setting"] == "small"
    assert sum(validate.case_seconds(r) for r in merged.values()) == 67.0


def test_darcy_column_converges(tmp_path):
    """The two coarsest Darcy columns of the small setting through the suite's own runner. Measured:
    error 0.064 % at dx 2 cm and 0.030 % at 1 cm (order 1.1; 0.20 % and 0.086 % before the shift's
    anti-pairing took a wall pair at the pore water's rest distance from the wall, docs/isph.md; 3.6 % and
    1.1 % while the side walls below the hanging column counted as wet). Bounds: 0.13 % and 0.06 % (about
    twice the measured, the SPEC target being 1 %) and a positive order."""
    c = validate.CASES["darcy_column"]
    runs, evaluate = c.build("small")
    rows = []
    for run in runs[:2]:
        row = validate.run_one(run, tmp_path, timeout=300)
        assert row["status"] == "completed", row
        row.update(evaluate(tmp_path / row.pop("out").split("/")[-1], run))
        rows.append(row)
    assert rows[0]["dx"] > rows[1]["dx"]
    assert rows[0]["error"] < 0.0013 and rows[1]["error"] < 0.0006, rows
    _, fit = validate.observed_orders([r["dx"] for r in rows], [r["error"] for r in rows])
    assert fit > 0


@pytest.mark.parametrize("axis, value, mode, outcome", [
    # measured: survives, volume drift -0.1 %; a jittered start must settle, not blow up
    ("jitter", "0.2 dx", "wcsph_biot", "survived"),
    # measured: stops at step ~10 on the density ratio (eq 49's coefficients 8x their defaults)
    ("dt", "8x", "wcsph_biot", "bounds"),
])
def test_stress_cells(tmp_path, axis, value, mode, outcome):
    cell = next(c for c in stress.cells([axis]) if c.value == value and c.mode == mode)
    row = stress.run_cell(cell, tmp_path, timeout=300)
    assert row["outcome"] == outcome, row
    if outcome == "survived":
        assert abs(row["volume_drift"]) < 0.01, row  # 1 %: ten times the measured drift
        assert row["energy_change"] < 0.0, row  # a dam break dissipates; energy must not be created
    else:
        assert "step" in row["message"] and "particle" in row["message"], row


def test_channel_startup_series():
    """The series is the steady parabola late and zero at the start (200 terms: the parabola's sine series
    converges as n^-3, so 1e-4 of the steady centre speed at t = 0 and exact to round-off at t = 10 s)."""
    L, nu, g = validate.CHANNEL_L, validate.CHANNEL_NU, validate.G
    x = np.linspace(0, L, 41)
    u_ss = g * L**2 / (8 * nu)
    assert np.abs(validate.channel_startup_velocity(x, 0.0)).max() < 1e-4 * u_ss
    np.testing.assert_allclose(validate.channel_startup_velocity(x, 10.0), g / (2 * nu) * x * (L - x),
                               atol=1e-9 * u_ss)


@pytest.mark.parametrize("mode, bound", [
    # measured RMS error over the slab's middle at 0.1 s, relative to the steady centre speed, at dx = L / 10:
    # isph 1.1 %, wcsph_biot 3.1 %; bounds 2 % and 5 % (about 1.7x the measured; a viscous term off by
    # 10 % moves the profile by ~5 % of u_ss at this time)
    ("isph", 0.02), ("wcsph_biot", 0.05)])
def test_channel_startup_matches_the_series(tmp_path, mode, bound):
    runs, evaluate = validate.CASES["channel_startup"].build("small")
    run = next(r for r in runs if r.variant == mode and r.dx == 0.002)
    row = validate.run_one(run, tmp_path, timeout=300)
    assert row["status"] == "completed", row
    m = evaluate(tmp_path / row["out"].split("/")[-1], run)
    assert m["error"] < bound, m


def test_taylor_green_decay_coarse(tmp_path):
    """The coarsest Taylor-Green run of the small setting (dx = L/16, 256 particles, 125 steps) through the
    suite's runner. Measured: largest |E / E_exact - 1| over 0.5 s 4.35 %, energy at the end 1.033 of the
    exact decay (exp(-4 nu k^2 t) = 0.45 of the start), velocity L2 error at the end 6.8 %. Bounds 1.5x the
    measured (6.5 %, 10 %): a missing viscous term leaves the energy 2.2x the exact at 0.5 s, and pairs
    across the periodic sides seen without the minimum image give errors of order 1."""
    c = validate.CASES["taylor_green"]
    runs, evaluate = c.build("small")
    run = max(runs, key=lambda r: r.dx)
    row = validate.run_one(run, tmp_path, timeout=300)
    assert row["status"] == "completed", row
    row.update(evaluate(tmp_path / row.pop("out").split("/")[-1], run))
    assert row["error"] < 0.065 and row["velocity L2 at end"] < 0.10, row
