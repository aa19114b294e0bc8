"""The causes of instability a solver detects inside a step, as the InstabilityError (or warning) the
driver reports: one-line messages "step S, t = T s: <quantity> ... (particle ids ...)" and their families
(exit codes in errors.py). The solvers and sph/solver_common.py call these; the driver's own checks
between steps are in guard.py, which re-exports them. Imports only the base modules (errors, backend)."""

from __future__ import annotations

import logging
import math

from .backend import ids_text
from .errors import InstabilityError

log = logging.getLogger("taichi_sph")


def where(step: int, time: float) -> str:
    return f"step {step}, t = {time:.6g} s"


def out_of_domain(cfg, step: int, time: float, ids, removed_total: int) -> None:
    """Particles the neighbour grid dropped (outside the domain): stop or warn, as guard.out_of_domain says."""
    ids = [int(i) for i in ids]
    if cfg.guard.out_of_domain == "error":
        raise InstabilityError(
            f"{where(step, time)}: {len(ids)} particle(s) left the domain (guard.out_of_domain: error) "
            f"(particle ids {ids_text(ids)})", step=step, time=time, quantity="position", particles=ids,
            family="domain")
    log.warning("%s: removed %d particle(s) that left the domain (ids %s); %d removed so far",
                where(step, time), len(ids), ids_text(ids), removed_total)


def neighbour_overflow_error(step: int, time: float, exc) -> InstabilityError:
    return InstabilityError(f"{where(step, time)}: {exc}", step=step, time=time, quantity="neighbour count",
                            particles=[exc.particle_id], family="bounds")


def non_finite_error(step: int, time: float, count: int, first_id: int, what: str) -> InstabilityError:
    return InstabilityError(
        f"{where(step, time)}: non-finite {what} at {count} particle(s) (first particle id {first_id})",
        step=step, time=time, quantity="non-finite state", particles=[first_id], family="nonfinite")


def solver_failure(step: int, time: float, iterations: int, residual: float, tolerance: float,
                   on_failure: str) -> None:
    """The PPE's CG ended above its tolerance: stop when it diverged (non-finite residual) or when
    isph.ppe.on_failure is `error`, else warn."""
    diverged = not math.isfinite(residual)
    msg = (f"{where(step, time)}: PPE solver {'diverged' if diverged else 'did not converge'} "
           f"({iterations} iterations, relative residual {residual:.3g} > {tolerance:g})")
    if on_failure == "error" or diverged:
        raise InstabilityError(msg, step=step, time=time, quantity="PPE residual", family="solver")
    log.warning(msg)


def time_step_error(step: int, time: float, dt: float, dt_min: float, what: str) -> InstabilityError:
    return InstabilityError(f"{where(step, time)}: the time step of {what} fell to {dt:.3g} s, below "
                            f"timestep.min = {dt_min:g} s", step=step, time=time, quantity="time step",
                            family="solver")
