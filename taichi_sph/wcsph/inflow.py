"""River inflow of mode wcsph_biot (config `inflow`): water added at a prescribed rate, so that a river
level rises behind a levee (seed 002 section 3.5: the river side rises, then stays).

Each inflow is a source box above the river, filled with water particles on the dx lattice that are held
out of the simulation (inactive) at the start (scene.inflow_particles places them). They are released one
lattice row at a time, lowest row first, so that the volume released by time t is rate (t - start)
rounded down to whole rows (a row holds its particle count times dx^dim of water), until the box is
empty. A released particle starts at rest, at the water's reference density, at its lattice place, and
falls into the river: the river level rises at rate / (width of the river) once the stream has reached
it. Mass enters, momentum does not (the particles start at rest), so the fall releases only the potential
energy of the source's height: keep the box low above the highest river level. Release times are a
function of the simulated time alone, so a resumed run releases the same rows at the same steps.
"""

from __future__ import annotations

import numpy as np


class Inflow:
    """Release schedule of the reserve particles (ids in the scene's order, which are particle ids)."""

    def __init__(self, cfg, rows_by_source: list[list[np.ndarray]]):
        self.dx, self.dim = cfg.dx, cfg.dim
        self.sources = list(zip(cfg.inflow, rows_by_source))
        self.done = None  # rows released per source; set from the time at the first call (resume)

    def reserve_ids(self) -> np.ndarray:
        ids = [row for _, rows in self.sources for row in rows]
        return np.concatenate(ids) if ids else np.zeros(0, np.int64)

    def _due(self, t: float) -> list[int]:
        out = []
        for src, rows in self.sources:
            vol = src.rate * max(t - src.start, 0.0)
            k, acc = 0, 0.0
            while k < len(rows) and acc + len(rows[k]) * self.dx**self.dim <= vol * (1 + 1e-9):
                acc += len(rows[k]) * self.dx**self.dim
                k += 1
            out.append(k)
        return out

    def release(self, t_before: float, t: float) -> np.ndarray:
        """Ids of the particles to release in the step from t_before to t (empty when none)."""
        if self.done is None:
            self.done = self._due(t_before)
        due = self._due(t)
        ids = []
        for s, ((_, rows), k) in enumerate(zip(self.sources, due)):
            ids += rows[self.done[s]:k]
            self.done[s] = max(self.done[s], k)
        return np.concatenate(ids) if ids else np.zeros(0, np.int64)


def activate(solver, ids: np.ndarray) -> None:
    """Make the particles with these ids active, at rest, at the water's reference density and zero
    gauge pressure (host side, then a neighbour search puts them into the lists)."""
    cur = solver.ids.to_numpy()
    sel = np.isin(cur, ids)
    active = solver.active.to_numpy()
    active[sel] = 1
    solver.active.from_numpy(active)
    for name, value in (("v", 0.0), ("a", 0.0), ("rate", 0.0), ("rho", solver.rho_w), ("p", 0.0)):
        field = getattr(solver, name)
        arr = field.to_numpy()
        arr[sel] = value
        field.from_numpy(arr)
    if solver.has_soil:
        arr = solver.adrag.to_numpy()
        arr[sel] = 0.0
        solver.adrag.from_numpy(arr)
    q = solver.q.to_numpy()
    q[sel, solver.Q_RHO] = solver.rho_w
    q[sel, solver.Q_PR] = 0.0
    solver.q.from_numpy(q)

