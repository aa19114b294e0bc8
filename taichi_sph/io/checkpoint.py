"""Checkpoints: restart points of a run, one small HDF5 file each in ``<run>.checkpoints/`` beside the
run file ``<run>.h5``, named ``step_<step>.h5`` (ten digits, so names sort by step).

Each file holds

- root attributes ``format = "taichi-sph-checkpoint"``, ``format_version = 1``, ``time`` (s), ``step``,
  ``run_file`` (the run file's name);
- ``/solver/<name>``: the solver's `state()` (per-particle arrays in the solver's own order, scalars as
  0-d datasets), exactly as the solver gave them;
- attribute ``driver``: the step loop's own state as JSON (time, next frame time, last diagnostics,
  how many frames, diagnostic rows and probe samples the run file held at that moment).

A checkpoint is written to a temporary name and renamed into place, so a run killed while writing
one leaves the previous checkpoints intact. Only the newest `keep` are kept.

This module imports numpy and h5py only (never a solver, never taichi).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

FORMAT = "taichi-sph-checkpoint"
FORMAT_VERSION = 1


class CheckpointError(ValueError):
    """No checkpoint to resume from, or a file that is not one."""


def checkpoint_dir(run_path: str | Path) -> Path:
    """``<run>.checkpoints`` beside ``<run>.h5``."""
    return Path(run_path).with_suffix(".checkpoints")


def list_checkpoints(run_path: str | Path) -> list[Path]:
    """Checkpoint files of a run, oldest first."""
    d = checkpoint_dir(run_path)
    if not d.is_dir():
        return []
    return sorted(p for p in d.glob("step_*.h5") if p.is_file())


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def write_checkpoint(run_path: str | Path, step: int, time: float, solver_state: dict, driver: dict,
                     keep: int) -> Path:
    """Write one checkpoint (atomically) and delete all but the newest `keep`; returns its path."""
    d = checkpoint_dir(run_path)
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"step_{int(step):010d}.h5"
    tmp = d / f".{path.name}.tmp"
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["time"] = float(time)
        f.attrs["step"] = int(step)
        f.attrs["run_file"] = Path(run_path).name
        f.attrs["driver"] = json.dumps(driver, default=_plain)
        g = f.create_group("solver")
        for name, value in solver_state.items():
            g.create_dataset(name, data=np.asarray(value))
    os.replace(tmp, path)
    for old in list_checkpoints(run_path)[: -int(keep)]:
        old.unlink(missing_ok=True)
    return path


def read_checkpoint(path: str | Path) -> tuple[dict, dict, dict]:
    """(solver state, driver state, root attributes) of a checkpoint file."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("format") != FORMAT:
                raise CheckpointError(f"{path}: not a taichi-sph checkpoint")
            state = {}
            for name, ds in f["solver"].items():
                value = ds[()]
                state[name] = value.item() if ds.ndim == 0 else np.asarray(value)
            driver = json.loads(f.attrs["driver"])
            attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in f.attrs.items() if k != "driver"}
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot read checkpoint ({str(exc).splitlines()[0]})") from None
    return state, driver, attrs


def latest_checkpoint(run_path: str | Path) -> Path:
    """The newest checkpoint of a run; CheckpointError when there is none."""
    found = list_checkpoints(run_path)
    if not found:
        raise CheckpointError(f"{run_path}: no checkpoint to resume from (looked in {checkpoint_dir(run_path)})")
    return found[-1]
