"""The solver contract: what the driver (run.py), checkpoints, probes, the stability guard and tools/ use
of a solver, written once as a Protocol that both modes' solvers satisfy (tests/test_contract.py), and
the codes of the time-step limits that bind a step (run file /diagnostics/dt_limit).

This module imports nothing from the package: the solvers, the driver and the registry (solvers.py)
all import it.
"""

from __future__ import annotations

from typing import Any, Mapping, Protocol, runtime_checkable

import numpy as np

#: dt_limit codes: the step was a number given as `dt` (fixed), or bound by the CFL, viscous or force limit
#: (run.TimeStepper for mode isph, eq 49 for mode wcsph_biot), by timestep.max, or shortened to land on
#: a frame or end time
DT_FIXED, DT_CFL, DT_VISCOUS, DT_FORCE, DT_MAX, DT_OUTPUT = range(6)
#: names of the dt_limit codes, for the log and the run file
DT_LIMIT_NAMES = {DT_FIXED: "fixed", DT_CFL: "cfl", DT_VISCOUS: "viscous", DT_FORCE: "force", DT_MAX: "max",
                  DT_OUTPUT: "output"}


@runtime_checkable
class Solver(Protocol):
    """A solver of one mode, built as `cls(cfg, scene)` from a validated Config and its Scene (scene.py).

    Particle arrays live in the solver's own order (cell order, reordered by the neighbour search);
    everything it hands out (`fields_by_id`) is in particle-id order."""

    # ---- sizes and constants the driver writes to the run file
    #: all particles (water, wall, soil, air, inactive reserve)
    n: int
    #: water particles
    n_water: int
    #: fluid particles a step moves (water and air): the count of particle-steps per second
    n_fluid: int
    #: reference water particle mass (kg, per metre in 2D) and water density (kg/m^3)
    mass: float
    rho_w: float
    #: air's reference density (kg/m^3); None when the mode has no air
    rho_a: float | None
    #: kernel support radius (m)
    re: float
    #: |gravity| (m/s^2), for the time-step limits
    g_abs: float
    #: extra run-file attributes of this solver (e.g. the pore water's stiffness ratio)
    run_attrs: Mapping[str, Any]
    #: the per-step diagnostics `step` reports (a subset of run.DIAG_COLUMNS)
    diagnostic_names: tuple[str, ...]
    #: True when the solver sets the time step itself (`propose_dt`, mode wcsph_biot eq 49); else the
    #: driver's TimeStepper chooses it
    proposes_dt: bool

    # ---- state the driver reads and sets
    step_count: int
    #: simulated time (s); the driver sets it after each step
    time: float
    #: particles removed after leaving the domain (guard.out_of_domain: remove)
    removed_total: int
    #: wall seconds per phase of the step
    timers: dict[str, float]

    def initial_diagnostics(self) -> dict:
        """Prepare the first step (neighbour lists, forces at t = 0); the diagnostics at t = 0."""

    def step(self, dt: float) -> dict:
        """Advance by dt; the diagnostics of `diagnostic_names`. Raises InstabilityError (guard.py)."""

    def propose_dt(self) -> tuple[float, int]:
        """The solver's own time step and its dt_limit code (only called when `proposes_dt`)."""

    def fields_by_id(self) -> dict[str, np.ndarray]:
        """Frame fields (position, velocity, pressure, density, active, ...) in particle-id order."""

    def guard_fields(self) -> dict[str, np.ndarray]:
        """The fields the guard's full check reads (position, density, active, and `finite`: position,
        velocity, pressure and density all finite), in particle-id order; cheaper than fields_by_id
        (SolverCommon gives it)."""

    def max_speed_bound(self) -> float:
        """The speed above which the guard stops the run (m/s)."""

    def max_pore_pressure_bound(self) -> float | None:
        """The pore-pressure magnitude of a soil particle above which the guard stops the run (Pa); None:
        no bound (no soil with a pore pressure)."""

    def state(self) -> dict:
        """The whole state, for a checkpoint (sph/state.py)."""

    def load_state(self, state: dict) -> None:
        """Continue from a `state()` of a solver built from the same config (StateMismatchError if not)."""
