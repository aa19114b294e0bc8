"""Solver state as host arrays, for checkpoints: the generic half of `solver.state()` and
`solver.load_state(state)`.

A solver names the Taichi fields and the Python attributes that carry over from one step to the
next; `snapshot` copies them into a flat dict ``{name: numpy array or Python scalar}`` and `restore`
writes such a dict back. Fields are copied whole, in the solver's current (cell-sorted) particle
order, so that the step after a restore does exactly what the step after the snapshot did.
Neighbour lists that are kept between steps (Verlet lists) are saved under ``grid.nbr_count`` and
``grid.nbr`` (trimmed to the longest list).

This module imports numpy and taichi only.
"""

import numpy as np

NBR_COUNT, NBR = "grid.nbr_count", "grid.nbr"


class StateMismatchError(ValueError):
    """A saved state that does not fit the solver (other particle count, other fields)."""


def snapshot(owner, fields, scalars, grid=None) -> dict:
    """``{name: array}`` for each field attribute of `owner`, ``{name: value}`` for each scalar
    attribute (numbers, or numpy arrays kept on the host), and the neighbour lists of `grid`."""
    out = {}
    for name in fields:
        out[name] = getattr(owner, name).to_numpy()
    for name in scalars:
        value = getattr(owner, name)
        out[name] = np.array(value) if isinstance(value, np.ndarray) else value
    if grid is not None:
        counts = grid.nbr_count.to_numpy()
        width = max(int(counts.max(initial=0)), 1)
        out[NBR_COUNT] = counts
        out[NBR] = grid.nbr.to_numpy()[:, :width]
    return out


def restore(owner, state: dict, fields, scalars, grid=None) -> None:
    """Write a `snapshot` back. Keys the solver does not list are an error, and so are missing keys
    and arrays of another shape."""
    expected = set(fields) | set(scalars) | ({NBR_COUNT, NBR} if grid is not None else set())
    missing = sorted(expected - set(state))
    extra = sorted(set(state) - expected)
    if missing or extra:
        what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(extra)}"
        raise StateMismatchError(f"saved state does not fit this solver ({what})")
    for name in fields:
        field = getattr(owner, name)
        arr = np.asarray(state[name])
        current = field.to_numpy()
        if arr.shape != current.shape:
            raise StateMismatchError(f"saved state '{name}' has shape {arr.shape}, the solver needs {current.shape}")
        field.from_numpy(arr.astype(current.dtype, copy=False))
    for name in scalars:
        value = state[name]
        current = getattr(owner, name)
        if isinstance(current, np.ndarray):
            value = np.array(value, dtype=current.dtype).reshape(current.shape)
        elif isinstance(current, bool):
            value = bool(value)
        elif isinstance(current, int):
            value = int(value)
        elif isinstance(current, float):
            value = float(value)
        setattr(owner, name, value)
    if grid is not None:
        counts = np.asarray(state[NBR_COUNT])
        lists = np.asarray(state[NBR])
        cap = grid.nbr.shape
        if counts.shape != tuple(grid.nbr_count.shape) or lists.shape[0] != cap[0] or lists.shape[1] > cap[1]:
            raise StateMismatchError(f"saved neighbour lists {lists.shape} do not fit the grid {cap}")
        full = np.zeros(cap, dtype=np.int32)
        full[:, : lists.shape[1]] = lists
        grid.nbr_count.from_numpy(counts.astype(np.int32))
        grid.nbr.from_numpy(full)

