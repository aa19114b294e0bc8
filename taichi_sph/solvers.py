"""The registry of solvers: config `mode` -> the class that runs it (each satisfies contract.Solver).
The driver (run.py) and the benchmarks in tools/ build their solver here. Solver modules import Taichi,
so each is imported when its mode is asked for."""

from __future__ import annotations

import importlib

from .contract import Solver

#: mode -> "module:class" of its solver
SOLVERS = {
    "isph": "taichi_sph.isph.solver:ISPHSolver",
    "wcsph_biot": "taichi_sph.wcsph.solver:WCSPHSolver",
}


def solver_class(mode: str) -> type:
    """The solver class of a mode (KeyError naming the known modes if there is none)."""
    try:
        module, name = SOLVERS[mode].split(":")
    except KeyError:
        raise KeyError(f"no solver for mode {mode!r} (modes: {', '.join(SOLVERS)})") from None
    return getattr(importlib.import_module(module), name)


def make_solver(cfg, scene) -> Solver:
    """The solver of the config's mode, built from the validated config and its scene (scene.build_scene)."""
    return solver_class(cfg.mode)(cfg, scene)
