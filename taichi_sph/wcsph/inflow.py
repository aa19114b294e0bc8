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

A source with a target `level` history (and the `water_level` probe `level_probe` that reads the river)
is a river held at a level, or raised at a rate, by feedback: at each sample of its probe the source opens
when the reading is below the target at that time and closes otherwise, and while open it releases at
`rate`, whole rows as before. The target is then followed from below within the stream's lag: water
released during the fall time t_f from the box to the river arrives after the gate closed, so the level
overshoots the target by at most about rate t_f / (river width), plus one row, plus one control interval
at `rate`. With `level_smoothing` the gate reads the mean over that window instead of the last sample
(a stilling well: the stream's impact raises waves that swing one reading by a few dx); a resumed run
goes on with the window's readings. The probe's samples are the level-time history in the run file. Its rows
released, its released volume and its gate are part of the solver's checkpoint (`state`), so a resumed
run goes on from them.
"""

from __future__ import annotations

import logging
import math

import numpy as np

log = logging.getLogger("taichi_sph")


class Inflow:
    """Release schedule of the reserve particles (ids in the scene's order, which are particle ids)."""

    def __init__(self, cfg, rows_by_source: list[list[np.ndarray]]):
        self.dx, self.dim = cfg.dx, cfg.dim
        self.sources = list(zip(cfg.inflow, rows_by_source))
        self.done = None  # rows released per source; set from the time at the first call (resume)
        # level-controlled sources: volume released so far and the gate (closed until the first reading)
        self.volume = [0.0] * len(self.sources)
        self.gate = [False] * len(self.sources)
        self.recent: list[list] = [[] for _ in self.sources]  # (t, reading) within level_smoothing
        self.empty: set[int] = set()  # controlled sources found empty (warned once)
        # the most readings a smoothing window holds (their probe's interval; default output.every)
        every = {p.name: float(p.every or cfg.output.every) for p in getattr(cfg, "probes", [])}
        spans = [math.ceil(src.level_smoothing / every.get(src.level_probe, math.inf)) + 2
                 for src, _ in self.sources if src.level is not None]
        self.window = max([1, *spans])

    @property
    def controlled(self) -> bool:
        """Whether some source follows a target level (its state is then part of a checkpoint)."""
        return any(src.level is not None for src, _ in self.sources)

    def reserve_ids(self) -> np.ndarray:
        ids = [row for _, rows in self.sources for row in rows]
        return np.concatenate(ids) if ids else np.zeros(0, np.int64)

    def target(self, k: int, t: float) -> float:
        """Target river level of source k at time t: linear in the `level` history, held at its ends."""
        times, levels = zip(*self.sources[k][0].level)
        return float(np.interp(t, times, levels))

    def observe(self, t: float, readings: dict) -> None:
        """Open or close the level-controlled sources from their probes' readings at time t: the mean
        of the readings over the last `level_smoothing` seconds against the target at t."""
        for k, (src, _) in enumerate(self.sources):
            if src.level_probe in readings:
                recent = [(s, v) for s, v in self.recent[k] if s > t - src.level_smoothing]
                recent.append((t, float(readings[src.level_probe])))
                self.recent[k] = recent
                level = sum(v for _, v in recent) / len(recent)
                self.gate[k] = t >= src.start and level < self.target(k, t)

    def _rows_within(self, rows: list, vol: float) -> int:
        """Rows, lowest first, whose water fits in the volume `vol`."""
        k, acc = 0, 0.0
        while k < len(rows) and acc + len(rows[k]) * self.dx**self.dim <= vol * (1 + 1e-9):
            acc += len(rows[k]) * self.dx**self.dim
            k += 1
        return k

    def _due(self, t: float) -> list[int]:
        return [self._rows_within(rows, src.rate * max(t - src.start, 0.0)) for src, rows in self.sources]

    def release(self, t_before: float, t: float) -> np.ndarray:
        """Ids of the particles to release in the step from t_before to t (empty when none)."""
        if self.done is None:
            self.done = [0 if src.level is not None else k
                         for (src, _), k in zip(self.sources, self._due(t_before))]
        due = self._due(t)
        ids = []
        for s, (src, rows) in enumerate(self.sources):
            k = due[s]
            if src.level is not None:
                if self.gate[s]:
                    self.volume[s] += src.rate * max(t - max(t_before, src.start), 0.0)
                k = self._rows_within(rows, self.volume[s])
            ids += rows[self.done[s]:k]
            self.done[s] = max(self.done[s], k)
            if src.level is not None and self.gate[s] and self.done[s] == len(rows) and s not in self.empty:
                self.empty.add(s)
                log.warning("inflow[%d] is empty at t = %.4g s while its river (probe %s) is below the "
                            "target level %.4g m: make its box larger", s, t, src.level_probe,
                            self.target(s, t))
        return np.concatenate(ids) if ids else np.zeros(0, np.int64)

    @property
    def state(self) -> np.ndarray:
        """A checkpoint's `inflow_state`, one column per source: rows released, volume released, gate, then
        the readings in the smoothing window as (t, value) pairs, padded with NaN to a fixed length."""
        arr = np.full((3 + 2 * self.window, len(self.sources)), np.nan)
        arr[0] = self.done if self.done is not None else -1
        arr[1] = self.volume
        arr[2] = [float(g) for g in self.gate]
        for k, recent in enumerate(self.recent):
            for m, (t, v) in enumerate(recent[-self.window:]):
                arr[3 + 2 * m, k], arr[4 + 2 * m, k] = t, v
        return arr

    @state.setter
    def state(self, arr) -> None:
        arr = np.asarray(arr, dtype=np.float64).reshape(3 + 2 * self.window, len(self.sources))
        self.done = None if arr[0, 0] < 0 else [int(v) for v in arr[0]]
        self.volume = [float(v) for v in arr[1]]
        self.gate = [bool(v) for v in arr[2]]
        pairs = arr[3:].reshape(self.window, 2, len(self.sources))
        self.recent = [[(float(t), float(v)) for t, v in pairs[:, :, k] if np.isfinite(t)]
                       for k in range(len(self.sources))]


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
        arr = solver.soil.adrag.to_numpy()
        arr[sel] = 0.0
        solver.soil.adrag.from_numpy(arr)
    q = solver.q.to_numpy()
    q[sel, solver.Q_RHO] = solver.rho_w
    q[sel, solver.Q_PR] = 0.0
    solver.q.from_numpy(q)

