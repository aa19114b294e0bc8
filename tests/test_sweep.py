"""taichi-sph sweep: a sweep of tiny runs on 2 local workers and on a real Dask LocalCluster gives the
table with the right metrics; failed runs are recorded with their cause; finished runs are skipped."""

import argparse
import csv
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.metrics import reduce
from taichi_sph.sweep import plan_from_args, read_table
from tests.conftest import cli_env

DATA = Path(__file__).parent / "data"
RHO_G = 1000.0 * 9.81
DX = 0.04
DEPTHS = {"shallow": 0.16, "deep": 0.24}
METRICS = ("p_final", "p_half", "vol_mean", "ke_max")


def _sweep(run_cli, out, *extra):
    return run_cli("sweep", DATA / "sweep_tank_sweep.yaml", "--out", out, *extra, timeout=600)


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "local"
    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "-m", "taichi_sph.cli", "sweep", str(DATA / "sweep_tank_sweep.yaml"), "--out", str(out),
           "--workers", "2"]
    proc = subprocess.run(cmd, check=False, cwd=root, env=cli_env(), capture_output=True, text=True, timeout=600)
    return out, proc


def _by_case(table):
    return {c: {k: v[i] for k, v in table.items()} for i, c in enumerate(table["case"])}


def test_local_sweep_table(local_sweep):
    out, proc = local_sweep
    # one case fails on purpose: the sweep goes on and says so by its exit code
    assert proc.returncode == 1, proc.stderr
    rows = _by_case(read_table(out / "sweep.h5"))
    assert list(rows) == ["shallow", "deep", "bad"]
    with open(out / "sweep.csv", newline="", encoding="utf-8") as f:
        csv_rows = list(csv.DictReader(f))
    assert [r["case"] for r in csv_rows] == ["shallow", "deep", "bad"]
    assert [r["water.0.max"] for r in csv_rows] == ["[0.4, 0.16]", "[0.4, 0.24]", ""]
    assert float(csv_rows[1]["p_final"]) == rows["deep"]["p_final"]  # shortest round-trip repr
    assert (out / "sweep.png").is_file()

    bad = rows["bad"]
    assert bad["status"] == "unstable"
    assert "guard.max_speed" in bad["cause"] and "step 1" in bad["cause"]

    for name, depth in DEPTHS.items():
        row = rows[name]
        assert row["status"] == "completed" and row["cause"] == ""
        # the metrics are what the run file's series give (recomputed here from the raw arrays)
        with RunFile(row["run_file"]) as rf:
            t, p = rf.probes()["p_mid"]
            _, vol = rf.probes()["vol"]
            tv = rf.probes()["vol"][0]
            ke = rf.diagnostics()["kinetic_energy"]
        assert row["p_final"] == p[-1]
        k = int(np.argmin(np.abs(t - 0.05)))
        assert abs(t[k] - 0.05) < 1e-9 and row["p_half"] == pytest.approx(p[k], rel=1e-12)
        assert row["vol_mean"] == pytest.approx(np.sum(0.5 * (vol[1:] + vol[:-1]) * np.diff(tv)) / (tv[-1] - tv[0]),
                                                rel=1e-12)
        assert row["ke_max"] == ke.max()
        # physics: a tank at rest. The gauge 0.1 m up reads rho g (H - 0.1) within rho g dx / 2 (where the
        # free surface lies is known to half a particle layer); the water volume is the block's, 0.4 H
        # (m^2 in 2D), as every particle stays in the tank
        assert row["p_final"] == pytest.approx(RHO_G * (depth - 0.1), abs=0.5 * RHO_G * DX)
        assert row["vol_mean"] == pytest.approx(0.4 * depth, rel=1e-9)
        assert row["steps"] == 50
    # the pressure difference between the two depths is rho g dH within 5 % (the surface offset cancels)
    dp = rows["deep"]["p_final"] - rows["shallow"]["p_final"]
    assert dp == pytest.approx(RHO_G * 0.08, rel=0.05)


def test_rerun_skips_finished_cases(local_sweep, run_cli, tmp_path):
    out, _ = local_sweep
    copy = tmp_path / "again"
    shutil.copytree(out, copy)
    before = {n: (copy / "runs" / f"{n}.h5").stat().st_mtime_ns for n in DEPTHS}
    proc = _sweep(run_cli, copy, "--workers", "2")
    assert proc.returncode == 1, proc.stderr
    for name in DEPTHS:
        assert f"{name}: finished before, skipped" in proc.stderr
        assert (copy / "runs" / f"{name}.h5").stat().st_mtime_ns == before[name]
    assert "bad: unstable" in proc.stderr  # failed cases run again
    assert _by_case(read_table(copy / "sweep.h5"))["deep"]["p_final"] == _by_case(read_table(out / "sweep.h5"))[
        "deep"]["p_final"]


def test_dask_local_cluster_gives_the_same_table(local_sweep, run_cli, tmp_path):
    distributed = pytest.importorskip("distributed")
    out, _ = local_sweep
    # one thread per worker, as the local sweep gave each of its 2 runs (2 cores / 2 workers): the
    # same arithmetic in the same order, so the metrics agree to the last bit
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        proc = _sweep(run_cli, tmp_path / "dask", "--scheduler", cl.scheduler_address)
    assert proc.returncode == 1, proc.stderr
    assert "Dask cluster" in proc.stderr
    local = _by_case(read_table(out / "sweep.h5"))
    remote = _by_case(read_table(tmp_path / "dask" / "sweep.h5"))
    assert list(remote) == list(local)
    for name in local:
        assert remote[name]["status"] == local[name]["status"]
        for m in METRICS:
            a, b = local[name][m], remote[name][m]
            assert (math.isnan(a) and math.isnan(b)) or a == b, (name, m, a, b)


def test_grid_is_every_combination():
    args = argparse.Namespace(sweep_file=None, config=str(DATA / "sweep_tank.yaml"), out=None, overrides=[],
                              param=["water[0].max=[0.4,0.16],[0.4,0.24]", "dt=0.002,0.001"], workers=None,
                              variant=None)
    plan = plan_from_args(args)
    names = [c["name"] for c in plan["cases"]]
    assert names == ["max-0.4x0.16_dt-0.002", "max-0.4x0.16_dt-0.001", "max-0.4x0.24_dt-0.002",
                     "max-0.4x0.24_dt-0.001"]
    assert plan["cases"][3]["config"].dt == 0.001
    assert plan["cases"][3]["config"].water[0].max == [0.4, 0.24]


def test_bad_sweep_input_is_one_line_and_writes_nothing(run_cli, tmp_path):
    out = tmp_path / "s"
    proc = run_cli("sweep", "--config", DATA / "sweep_tank.yaml", "--param", "dt=0.002,-1", "--out", out)
    assert proc.returncode == 2
    assert "config key 'dt'" in proc.stderr and proc.stderr.count("\n") == 1
    assert not out.exists()
    proc = run_cli("sweep", "--config", DATA / "sweep_tank.yaml", "--param", "metrics[0].probe=nowhere", "--out", out)
    assert proc.returncode == 2 and "metrics[0].probe" in proc.stderr
    assert not out.exists()
    proc = run_cli("sweep", "--config", DATA / "sweep_tank.yaml", "--variant", "deep", "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "--variant 'deep': not defined in the config (variants: none)" in proc.stderr
    assert not out.exists()


def test_metric_reductions_against_closed_forms():
    # v = sin(t) on [0, pi], 2001 samples: trapezoid and linear-interpolation errors are O(h^2) ~ 1e-6
    t = np.linspace(0.0, math.pi, 2001)
    v = np.sin(t)
    assert reduce(t, v, "mean") == pytest.approx(2.0 / math.pi, abs=1e-6)
    assert reduce(t, v, "first_above", level=0.5) == pytest.approx(math.pi / 6, abs=1e-6)
    assert reduce(t, v, "first_below", level=-0.1) != reduce(t, v, "first_below", level=-0.1)  # NaN: never
    assert reduce(t, v, "at", time=1.0) == pytest.approx(math.sin(1.0), abs=1e-6)
    assert math.isnan(reduce(t, v, "at", time=4.0))
    assert reduce(t, v, "max") == pytest.approx(1.0, abs=1e-6)
    assert reduce(t, v, "final") == v[-1]


def test_freefall_sweep_file_plans_the_three_porosities():
    args = argparse.Namespace(sweep_file=str(DATA.parent.parent / "configs" / "freefall_sweep.yaml"), config=None, out=None, overrides=[], param=[],
                              workers=None, variant=None)
    plan = plan_from_args(args)
    assert [c["config"].soil.regions[0].eps0 for c in plan["cases"]] == [0.3, 0.5, 0.8]
    assert [m.name for m in plan["cases"][0]["config"].metrics][:2] == ["arrival_time", "layer_volume_at_arrival"]


def test_dry_levee_sweep_runs_the_variant_over_the_permeability(tmp_path):
    """configs/embankment_dry_sweep.yaml: each case is the variant `dry` (its river, probes and metrics)
    at the sweep's dx and length, one per permeability; --variant replaces the file's variant; a variant
    the case file lacks is one line naming the option or the sweep file's key."""
    from taichi_sph.errors import InputError

    sweep = str(DATA.parent.parent / "configs" / "embankment_dry_sweep.yaml")

    def plan(variant=None, path=sweep):
        return plan_from_args(argparse.Namespace(sweep_file=path, config=None, variant=variant, out=None, param=[],
                                                 overrides=["wcsph.soil.start_from=null"], workers=None))

    p = plan()
    cfgs = [c["config"] for c in p["cases"]]
    assert p["variant"] == "dry"
    assert [c.wcsph.soil.permeability for c in cfgs] == [0.015, 0.03, 0.06]
    for cfg in cfgs:
        assert (cfg.dx, cfg.end_time) == (0.02, 20.0)
        assert cfg.description.endswith("[variant dry]")
        assert cfg.water[0].outside_soil and not cfg.air
        assert [m.name for m in cfg.metrics] == ["river_final", "front_at_14s", "front_final", "levee_water_final"]
    air = [c["config"] for c in plan("dry_air")["cases"]]
    assert len(air[0].air) == 3 and air[0].wcsph.xsph == 0.0 and air[0].dx == 0.02
    with pytest.raises(InputError, match=r"^--variant 'wet': not defined in the config \(variants: dry, "):
        plan("wet")
    bad = tmp_path / "s.yaml"
    bad.write_text(f"config: {Path(sweep).parent / 'embankment.yaml'}\nvariant: wet\n")
    with pytest.raises(InputError, match=rf"^sweep file '{bad}': key 'variant' 'wet': not defined"):
        plan(path=str(bad))


@pytest.mark.parametrize("text, expect", [
    ("config: a.yaml\nfoo: 1\nbar: 2\n", "unknown key 'bar' (keys: cases, config, grid, out, set, variant, workers)"),
    ("config: a.yaml\nvariant: [dry]\n", "key 'variant' must be the name of one of the case file's variants"),
    ("out: x\n", "key 'config' (the case file) is required"),
    ("config: 3\n", "key 'config' (the case file) is required"),
    ("config: a.yaml\nworkers: 0\n", "key 'workers' must be a positive integer"),
    ("config: a.yaml\nworkers: true\n", "key 'workers' must be a positive integer"),
    ("config: a.yaml\nset: [1]\n", "key 'set' must be a mapping of dotted keys"),
    ("config: a.yaml\ngrid: 3\n", "key 'grid' must be a mapping of dotted keys"),
    ("config: a.yaml\ncases: [1, 2]\n", "key 'cases' must be a list of mappings"),
])
def test_sweep_file_errors_are_one_line(tmp_path, text, expect):
    from taichi_sph.config.sweep import load_sweep_file
    from taichi_sph.errors import InputError

    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_sweep_file(path)
    assert str(err.value) == f"sweep file '{path}': {expect}"
