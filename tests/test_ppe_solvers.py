"""The two PPE solvers of mode isph (isph.ppe.type sparse_cg and ell_pcg) solve the same system:
the same pressure to the solver tolerance on a hydrostatic tank and on water in porous ground.

Both solvers are built from the same config and scene and take the same steps; the matrices come
from the one assembly function, so the pressures may differ only by what each CG leaves unsolved.
"""

import numpy as np
import pytest

from .conftest import ROOT

TOL = 1.0e-10


def _solver(path, extra, ppe_type, steps, dt, tol=TOL):
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    cfg = load_config(path, overrides=[f"isph.ppe.type={ppe_type}", f"isph.ppe.tolerance={tol:.1e}",
                                       "isph.ppe.max_iterations=20000", *extra])
    solver = ISPHSolver(cfg, build_scene(cfg))
    solver.initial_diagnostics()
    for _ in range(steps):
        last = solver.step(dt)
        assert last["cg_residual"] <= tol
    return solver


# the hydrostatic tank made small (20 x 15 water particles) to keep the dense condition number cheap
SMALL_TANK = ["tank.size=[0.2, 0.2]", "water=[{min: [0.0, 0.0], max: [0.2, 0.15]}]"]


@pytest.mark.parametrize("case, extra, ell_tol", [
    ("hydrostatic.yaml", SMALL_TANK, TOL),
    ("darcy_column.yaml", [], TOL),
    # the ELL solve in f32, to the smallest tolerance f32 reaches
    ("hydrostatic.yaml", [*SMALL_TANK, "isph.ppe.precision=f32"], 1.0e-5),
])
def test_sparse_and_ell_give_the_same_pressure(ti_cpu, case, extra, ell_tol):
    path = ROOT / "configs" / case
    sparse = _solver(path, [e for e in extra if "precision" not in e], "sparse_cg", 3, 1e-3)
    ell = _solver(path, extra, "ell_pcg", 3, 1e-3, ell_tol)
    assert ell.ppe.name == "ell_pcg" and sparse.ppe.name == "sparse_cg"
    if case == "darcy_column.yaml":
        assert ell.porous  # the porous-ground coefficients are in the system
    p_s, p_e = (s.fields_by_id()["pressure"] for s in (sparse, ell))
    water = sparse.fields_by_id()["density"] > 0  # every particle; walls carry interpolated pressure
    assert np.all(water)
    # Bound: each CG stops at |b - A x| <= tol |b|, so |x - x*| <= cond(A) tol |x*| for each, and
    # the two differ by at most cond(A) (TOL + ell_tol) |x*|. cond(A) is computed from the ELL matrix of the
    # last step (its 2-norm condition number, dense: the systems hold a few hundred rows). The
    # pressures of earlier steps enter only through positions, moved by dt |grad p| differences of
    # the same relative size, far below the bound.
    A = ell.ppe.to_csr(ell.n_water).toarray()
    cond = np.linalg.cond(A)
    assert cond < 1e6  # the bound below means something only for a well-conditioned PPE
    diff = np.linalg.norm(p_s - p_e) / np.linalg.norm(p_s)
    print(f"{case}: {ell.n_water} rows, cond {cond:.3g}, relative difference {diff:.3g}")
    assert diff <= cond * (TOL + ell_tol), (diff, cond)
    if ell_tol > TOL:
        assert ell.ppe.dtype == ti_cpu.f32
    # and a non-trivial pressure field was solved: hydrostatic, rho g H = 1.5 kPa at the bottom; the
    # Darcy slab drains freely (no head), so its water is at the surface value rho_w g dx / 2 = 49 Pa
    # throughout: measured 49.05-49.41 Pa in these first steps (49.0-51.9 Pa while the shift's
    # anti-pairing pushed the pore water off the slip walls; tests/test_isph_porous.py follows the slab
    # to 0.3 s); bound 0.5 Pa
    if case == "darcy_column.yaml":
        p_w = p_s[sparse.fields_by_id()["porosity"] < 1.0]
        assert np.all(np.abs(p_w - 49.05) < 0.5), (p_w.min(), p_w.max())
    else:
        assert np.max(np.abs(p_s)) > 100.0


def test_ell_row_overflow_widens_the_matrix_and_solves_the_same_system(ti_cpu):
    """A PPE row wider than isph.ppe.width (an interior row of water at rest has 20 water neighbours in
    2D; a width of 8 cannot hold it) makes the solver continue with a matrix 1.25 x wider than the row
    needs, once, and the pressure is that of the default width: the same rows in the same slot order,
    so the same system; bound cond(A) 2 TOL as above (two threads may sum the CG reductions in a
    different order)."""
    from taichi_sph.isph.solver import ppe_width

    narrow = _solver(ROOT / "configs" / "hydrostatic.yaml", [*SMALL_TANK, "isph.ppe.width=8"], "ell_pcg", 2, 1e-3)
    assert narrow.ppe_widenings == 1
    assert 20 <= narrow.ppe.max_nb <= 40, narrow.ppe.max_nb
    wide = _solver(ROOT / "configs" / "hydrostatic.yaml", SMALL_TANK, "ell_pcg", 2, 1e-3)
    assert wide.ppe_widenings == 0
    p_n, p_w = (s.fields_by_id()["pressure"] for s in (narrow, wide))
    cond = np.linalg.cond(wide.ppe.to_csr(wide.n_water).toarray())
    assert np.linalg.norm(p_n - p_w) <= cond * 2 * TOL * np.linalg.norm(p_w)
    assert np.max(np.abs(p_w)) > 100.0  # a hydrostatic field was solved
    from taichi_sph.config import load_config

    cfg = load_config(ROOT / "configs" / "hydrostatic.yaml")
    assert ppe_width(cfg) == 30  # 1.5 x the 20 lattice neighbours within 2.4 dx in 2D
