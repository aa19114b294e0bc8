"""Both modes' solvers satisfy the written solver contract (taichi_sph/contract.py) and are built
through the registry (taichi_sph/solvers.py)."""

import inspect

import numpy as np
import pytest

from taichi_sph.config import load_config
from taichi_sph.contract import DT_LIMIT_NAMES, Solver
from taichi_sph.run import DIAG_COLUMNS
from taichi_sph.solvers import SOLVERS, make_solver, solver_class

#: a still 2D tank, small enough to build in a second in either mode
TANK = {"dim": 2, "dx": 0.02, "end_time": 0.01, "dt": "auto",
        "tank": {"size": [0.2, 0.2]}, "water": [{"min": [0.0, 0.0], "max": [0.2, 0.1]}]}


def _methods():
    return [name for name, value in vars(Solver).items()
            if callable(value) and not name.startswith("_")]


def test_registry_covers_every_mode():
    from taichi_sph.config.schema import CASES

    assert set(SOLVERS) == set(CASES)
    with pytest.raises(KeyError, match="no solver for mode 'nope'"):
        solver_class("nope")


@pytest.mark.parametrize("mode", sorted(SOLVERS))
def test_solver_classes_have_the_contract_methods(mode):
    cls = solver_class(mode)
    for name in _methods():
        want = inspect.signature(getattr(Solver, name))
        have = inspect.signature(getattr(cls, name))
        assert list(have.parameters) == list(want.parameters), (cls.__name__, name)


@pytest.mark.parametrize("mode", sorted(SOLVERS))
def test_built_solvers_satisfy_the_contract(ti_cpu, mode):
    from taichi_sph.scene import build_scene

    cfg = load_config(data={**TANK, "mode": mode})
    scene = build_scene(cfg)
    solver = make_solver(cfg, scene)
    assert isinstance(solver, Solver)
    assert solver.n == scene.n and solver.n_fluid >= solver.n_water > 0
    assert set(solver.diagnostic_names) <= set(DIAG_COLUMNS)
    first = solver.initial_diagnostics()
    if solver.proposes_dt:
        dt, limit = solver.propose_dt()
        assert dt > 0 and limit in DT_LIMIT_NAMES
    else:
        with pytest.raises(NotImplementedError):
            solver.propose_dt()
        dt = 1e-3
    diag = solver.step(dt)
    assert set(solver.diagnostic_names) <= set(first) and set(solver.diagnostic_names) <= set(diag)
    assert solver.step_count == 1
    fields = solver.fields_by_id()
    for key in ("position", "velocity", "pressure", "density", "active"):
        assert len(fields[key]) == scene.n, key
    # frames are in particle-id order: the walls have not moved from the scene's places
    wall = np.asarray(scene.kind) == 1
    assert np.array_equal(fields["position"][wall], np.asarray(scene.position)[wall])
    # the guard's cheaper gather reads the same particles in the same order, and says which hold a
    # non-finite position, velocity, pressure or density: here none; then one particle's velocity is made
    # NaN and exactly its id is flagged
    checked = solver.guard_fields()
    assert set(checked) == {"position", "density", "pressure", "finite", "active"}
    for key in ("position", "density", "active"):
        assert np.array_equal(checked[key], fields[key]), key
    # pressure: the frames give walls their interpolated wall pressure, the guard reads none of them
    assert np.array_equal(checked["pressure"][~wall], fields["pressure"][~wall])
    assert checked["finite"].all()
    ids = solver.ids.to_numpy()
    v = solver.v.to_numpy()
    keep = v[3].copy()
    v[3] = np.nan
    solver.v.from_numpy(v)
    assert np.flatnonzero(~solver.guard_fields()["finite"]).tolist() == [int(ids[3])]
    v[3] = keep
    solver.v.from_numpy(v)
    state = solver.state()
    solver.step(dt)
    solver.load_state(state)
    assert solver.step_count == 1
    assert np.array_equal(solver.fields_by_id()["position"], fields["position"])


@pytest.mark.parametrize("mode", sorted(SOLVERS))
def test_a_runtime_without_room_for_a_solver_says_so(ti_cpu, mode, monkeypatch):
    """Taichi's LLVM backends hold at most 512 SNode trees in a runtime and crash the process, with no
    message, on the next one (a process that had built 46 porous solvers). A solver is not started
    where fewer than SOLVER_FIELD_TREES are left: here the limit is moved to just above the trees this
    runtime already holds, and the error names the count and the way out."""
    from taichi_sph import backend
    from taichi_sph.scene import build_scene

    cfg = load_config(data={**TANK, "mode": mode})
    scene = build_scene(cfg)
    used = backend.field_trees_used()
    monkeypatch.setattr(backend, "MAX_FIELD_TREES", used + backend.SOLVER_FIELD_TREES - 1)
    with pytest.raises(RuntimeError, match=f"holds {used} of its .* field trees.*its own process"):
        make_solver(cfg, scene)
    assert backend.field_trees_used() == used  # nothing was declared
    monkeypatch.setattr(backend, "MAX_FIELD_TREES", used + backend.SOLVER_FIELD_TREES)
    assert make_solver(cfg, scene).n == scene.n
