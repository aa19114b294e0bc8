"""With one CPU thread the neighbour search (counting sort, reorder, explicit lists) and a whole isph
step sequence are deterministic: two runs of the same input agree bitwise.

Runs in a subprocess: the test session's runtime uses every core, and the thread count is fixed
when Taichi starts.
"""

import os
import subprocess
import sys

from .conftest import ROOT

SCRIPT = r"""
import numpy as np
import taichi as ti

from taichi_sph.backend import taichi_options
ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=1, log_level=ti.WARN, **taichi_options())
from taichi_sph.config import load_config
from taichi_sph.isph.solver import ISPHSolver
from taichi_sph.scene import build_scene
from taichi_sph.sph.grid import NeighbourGrid

# grid: 3000 random particles in 2D, many per cell, a few outside the box
rng = np.random.default_rng(3)
n, dim, re = 3000, 2, 0.024
pos = rng.uniform(-0.01, 0.31, (n, dim))
out = []
for run in range(2):
    x = ti.Vector.field(dim, float, n)
    v = ti.field(float, n)
    act = ti.field(ti.i32, n)
    x.from_numpy(pos)
    v.from_numpy(np.arange(n, dtype=float))
    act.fill(1)
    g = NeighbourGrid(n, dim, [0, 0], [0.3, 0.3], re, 160)
    left = g.sort(x, act, n)
    g.reorder(x, n)
    g.reorder(v, n)
    g.reorder(act, n)
    g.build_neighbour_lists(x, act, n, re)
    out.append([left, g.perm.to_numpy(), x.to_numpy(), v.to_numpy(), g.nbr_count.to_numpy(), g.nbr.to_numpy()])
for a, b in zip(*out):
    assert np.array_equal(a, b)
assert out[0][4].sum() > 10 * n  # lists are not empty: the comparison means something

# isph: two solvers, the same dam break, 10 steps
cfg = load_config(data={"mode": "isph", "dim": 2, "dx": 0.01, "end_time": 1.0, "dt": 0.002,
                        "tank": {"size": [0.3, 0.2]}, "water": [{"min": [0, 0], "max": [0.1, 0.15]}]})
states = []
for run in range(2):
    s = ISPHSolver(cfg, build_scene(cfg))
    s.initial_diagnostics()
    for _ in range(10):
        s.step(0.002)
    f = s.fields_by_id()
    states.append((f["position"], f["velocity"], f["pressure"]))
for a, b in zip(*states):
    assert np.array_equal(a, b)
assert np.abs(states[0][1]).max() > 0.05  # the column is collapsing: not a trivial state
print("deterministic")
"""


def _run_script(path, text: str) -> str:
    """Run `text` as a Python script at `path` in its own process (its own Taichi runtime); its stdout."""
    path.write_text(text)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, str(path)], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=600, check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_one_thread_runs_are_bitwise_equal(tmp_path):
    assert "deterministic" in _run_script(tmp_path / "determinism.py", SCRIPT)


SCAN_SCRIPT = r"""
import numpy as np
import taichi as ti

from taichi_sph.backend import taichi_options
ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=1, log_level=ti.WARN, **taichi_options())
from taichi_sph.config import load_config
from taichi_sph.scene import build_scene
from taichi_sph.solvers import make_solver
from taichi_sph.sph import scan

cases = {
    "isph ell": {"mode": "isph", "dim": 2, "dx": 0.01, "end_time": 1.0, "dt": 0.002,
                 "tank": {"size": [0.3, 0.2]}, "water": [{"min": [0, 0], "max": [0.1, 0.15]}]},
    "wcsph": {"mode": "wcsph_biot", "dim": 2, "dx": 0.01, "end_time": 1.0, "dt": "auto",
              "tank": {"size": [0.3, 0.2]}, "water": [{"min": [0, 0], "max": [0.1, 0.15]}]},
}
cases["isph mg"] = dict(cases["isph ell"], isph={"ppe": {"type": "mg_pcg"}})
for name, data in cases.items():
    states = []
    for blocked in (False, True):
        scan.on_cpu = (lambda b=blocked: not b)
        cfg = load_config(data=data)
        s = make_solver(cfg, build_scene(cfg))
        scans = [s.grid._scan, getattr(s, "_row_scan", None) or s._moving_scan]
        if name == "isph mg":
            scans.append(s.ppe._cell_scan)
        assert all(p.blocked == blocked for p in scans), name
        # the wcsph passes over the moving list launch all n entries with the blocked scan (exact_grid)
        assert name.startswith("isph") or s.exact_grid == blocked, name
        s.initial_diagnostics()
        for _ in range(10):
            dt = 0.002 if name.startswith("isph") else s.propose_dt()[0]
            s.step(dt)
        f = s.fields_by_id()
        states.append((f["position"], f["velocity"], f["pressure"]))
    for a, b in zip(*states):
        assert np.array_equal(a, b), name
    assert np.abs(states[0][1]).max() > 0.01, name
print("same")
"""


def test_blocked_prefix_sums_leave_the_steps_as_they_were(tmp_path):
    """The blocked prefix sums that GPUs take (the grid's cells, the PPE's row numbers, the multigrid's
    cells, the moving list; sph/scan.py), forced here on the CPU, give every particle's position, velocity
    and pressure of the serial ones bit for bit, after 10 steps of a collapsing column in both modes. With
    them the wcsph passes run over all particles, the ones that do not move listed last (solver.exact_grid;
    with soil: test_returned_reductions_leave_the_steps_as_they_were)."""
    assert "same" in _run_script(tmp_path / "scan.py", SCAN_SCRIPT)


RETURN_SCRIPT = r"""
import numpy as np
import taichi as ti

from taichi_sph.backend import taichi_options
ti.init(arch=ti.cpu, default_fp=ti.f32, cpu_max_num_threads=1, log_level=ti.WARN, **taichi_options())
from taichi_sph.config import load_config
from taichi_sph.config.load import read_yaml
from taichi_sph.scene import build_scene
from taichi_sph.solvers import make_solver
from taichi_sph.sph import scan
from taichi_sph.wcsph import solver as wsolver

water = {"mode": "wcsph_biot", "dim": 2, "dx": 0.01, "end_time": 1.0, "dt": "auto",
         "tank": {"size": [0.3, 0.2]}, "water": [{"min": [0, 0], "max": [0.1, 0.15]}]}
soil = read_yaml("configs/consolidation.yaml")
soil.pop("variants", None)
piston = dict(water, obstacles=[{"min": [0.25, 0.0], "max": [0.27, 0.12],
                                 "motion": {"velocity": [-0.2, 0.0], "ramp": 0.005}}])
for name, data in {"water": water, "soil": soil, "piston": piston}.items():
    states = []
    for returned in (False, True):
        wsolver.RETURN_REDUCTIONS = returned
        scan.on_cpu = (lambda b=returned: not b)  # with the blocked prefix sums, the passes over all n
        cfg = load_config(data=data)
        s = make_solver(cfg, build_scene(cfg))
        assert s.returns_reductions == returned and s.exact_grid == returned
        s.motion._host_arrays = not returned  # the bodies' motion by value, as on GPUs
        assert s.motion.any == (name == "piston")
        s.initial_diagnostics()
        reds = []
        for _ in range(10):
            s.step(s.propose_dt()[0])
            reds.append(np.concatenate([s.red_kick, s.red_pairs]))
        f = s.fields_by_id()
        states.append((f["position"], f["velocity"], f["pressure"], np.array(reds)))
    for a, b in zip(*states):
        assert np.array_equal(a, b), name
    assert np.abs(states[0][1]).max() > 0.0, name
print("same")
"""


def test_returned_reductions_leave_the_steps_as_they_were(tmp_path):
    """The step's reductions returned by its kernels, a moving body's velocity passed by value, and the
    passes over all n entries of the moving list after its blocked prefix sum (GPUs' ways: wcsph/solver.py
    RETURN_REDUCTIONS and exact_grid, sph/wall_motion.py), forced here on the CPU, give the reductions, and
    every particle's position, velocity and pressure, of the CPU's ways bit for bit, after 10 steps of a
    collapsing column, of the consolidation column (the soil's passes) and of a column pushed by a piston
    (f32: the reductions pass through f64 and back exactly)."""
    assert "same" in _run_script(tmp_path / "returned.py", RETURN_SCRIPT)


SERIAL_SCRIPT = r"""
import numpy as np
import taichi as ti

from taichi_sph.backend import taichi_options
ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=1, log_level=ti.WARN, **taichi_options())
from taichi_sph.linalg import ell_pcg
from tests.test_ell_pcg import random_spd, sph_lattice_ppe

for A, b in (sph_lattice_ppe((30, 30))[:2], random_spd()[:2]):
    n = A.shape[0]
    width = int(np.diff(A.indptr).max())
    runs = []
    for rows in (0, n, n):  # parallel loops, then twice the serial solve in one launch (SERIAL_ROWS)
        ell_pcg.SERIAL_ROWS = rows
        solver = ell_pcg.EllPCG(n, width, 1e-10, 5000)
        solver.load_csr(A.indptr, A.indices, A.data, b, np.zeros(n))
        it, res, ok = solver.solve()
        x = solver.x.to_numpy()[:n]
        assert solver._serial == (rows == n) and ok
        assert np.linalg.norm(b - A @ x) / np.linalg.norm(b) <= 1e-10  # the true residual, not the solver's word
        runs.append((it, res, x))
    # the serial solve is deterministic
    assert runs[1][:2] == runs[2][:2] and np.array_equal(runs[1][2], runs[2][2])
    # and differs from the parallel loops only in the order its dot products are summed: the same count
    # (121 and 36 iterations), x within 4.9e-13 / 4.1e-15 of the largest |x| (measured; bound 4x the
    # larger, 400x below the tolerance)
    assert runs[0][0] == runs[1][0], (runs[0][:2], runs[1][:2])
    diff = np.abs(runs[0][2] - runs[1][2]).max() / np.abs(runs[0][2]).max()
    assert diff < 2e-12, diff
print("same")
"""


def test_serial_small_systems_solve_as_one_thread(tmp_path):
    """EllPCG's serial solve of a small system on the CPU (ell_pcg.SERIAL_ROWS: all iterations in one launch
    on the calling thread) against its parallel loops on one thread (an SPH lattice PPE and a random SPD
    matrix): bit for bit the same on a second run, and the same solve up to the summation order of its dot
    products (LLVM may reorder a reduction inside a kernel's loop, not across launches)."""
    assert "same" in _run_script(tmp_path / "serial.py", SERIAL_SCRIPT)
