"""Frames to draw and the scalar fields that colour them.

A frame source gives, for frame ``i``: its time, particle positions, the ``active`` mask and any
field; plus the run's ``dim``, ``dx``, particle ``kind`` and soil-marker positions. Two sources:
a run file (:class:`RunSource`) and snapshot files written while a run goes (:class:`SnapshotSource`,
one ``.npz`` per frame, see :func:`save_snapshot`).

Colour fields: any scalar frame field (``pressure``, ``density``, ``porosity``, ...); a vector
field's magnitude under its own name (``velocity``) or ``speed`` (= |velocity|); one component as
``<field>_x|_y|_z`` (``velocity_z``); and ``kind`` (0 water, 1 wall, 2 soil, 3 air).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io.hdf5 import RunFile, unit_for
from ..kinds import KIND_NAMES

AXES = "xyz"


class FrameSource:
    """Common interface; subclasses fill the attributes and implement `times`, `read`, `unit`."""

    dim: int
    dx: float
    kind: np.ndarray
    markers: np.ndarray | None
    field_names: list[str]
    stem: str

    @property
    def n_frames(self) -> int:
        return len(self.times)

    @property
    def times(self) -> np.ndarray:
        raise NotImplementedError

    def label(self, i: int) -> int:
        """Frame number used in file names (the frame's index in the run)."""
        return i

    def read(self, name: str, i: int) -> np.ndarray:
        raise NotImplementedError

    def unit(self, name: str) -> str:
        raise NotImplementedError

    def close(self) -> None:
        pass


class RunSource(FrameSource):
    def __init__(self, run: RunFile):
        self.run = run
        self.dim = run.dim
        self.dx = run.dx
        self.kind = run.kind
        mk = run.markers()
        self.markers = mk.get("position") if mk else None
        self.field_names = run.field_names
        self._units = run.units
        self._times = run.times
        self.stem = run.path.stem

    @property
    def times(self) -> np.ndarray:
        return self._times

    def read(self, name: str, i: int) -> np.ndarray:
        return self.run.field(name, i)

    def unit(self, name: str) -> str:
        return self._units.get(name) or unit_for(name, self.dim)

    def close(self) -> None:
        self.run.close()


def save_snapshot(path: str | Path, *, index: int, time: float, dim: int, dx: float, kind: np.ndarray,
                  fields: dict, units: dict, markers: np.ndarray | None, stem: str) -> Path:
    """One frame with what drawing it needs, as ``.npz`` (written to a temporary name, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part.npz")
    arrays = {f"field_{k}": np.asarray(v) for k, v in fields.items()}
    if markers is not None:
        arrays["markers"] = np.asarray(markers)
    meta = {"index": int(index), "time": float(time), "dim": int(dim), "dx": float(dx), "units": units, "stem": stem}
    np.savez(tmp, kind=np.asarray(kind, dtype=np.int8), meta=np.asarray(json.dumps(meta)), **arrays)
    tmp.replace(path)
    return path


class SnapshotSource(FrameSource):
    """Snapshot files (one frame each) of one run."""

    def __init__(self, paths: Sequence[str | Path]):
        if not paths:
            raise ValueError("no snapshot files")
        self._data = []
        for p in paths:
            with np.load(p) as z:
                meta = json.loads(str(z["meta"]))
                fields = {k[6:]: z[k] for k in z.files if k.startswith("field_")}
                self._data.append((meta, fields, z["kind"], z["markers"] if "markers" in z.files else None))
        meta0, fields0, kind0, markers0 = self._data[0]
        self.dim = int(meta0["dim"])
        self.dx = float(meta0["dx"])
        self.kind = kind0
        self.markers = markers0
        self.field_names = list(fields0)
        self._units = dict(meta0["units"])
        self.stem = str(meta0["stem"])

    @property
    def times(self) -> np.ndarray:
        return np.asarray([m["time"] for m, *_ in self._data], dtype=float)

    def label(self, i: int) -> int:
        return int(self._data[i][0]["index"])

    def read(self, name: str, i: int) -> np.ndarray:
        fields = self._data[i][1]
        if name not in fields:
            raise KeyError(f"snapshot has no field {name!r} (have {sorted(fields)})")
        return fields[name]

    def unit(self, name: str) -> str:
        return self._units.get(name) or unit_for(name, self.dim)


# ---- colour fields ------------------------------------------------------------------------------


def colour_fields(src: FrameSource) -> list[str]:
    """Every name `scalar_field` accepts for this source."""
    names = ["kind"]
    if src.n_frames == 0:
        return names
    for name in src.field_names:
        if name == "position":
            continue
        shape = np.shape(src.read(name, 0))
        if len(shape) == 1:
            names.append(name)
        elif len(shape) == 2 and shape[1] <= 3:  # a vector: its magnitude and its components
            names += [name, *(f"{name}_{a}" for a in AXES[: shape[1]])]
            if name == "velocity":
                names.append("speed")
    return names


def resolve_field(src: FrameSource, name: str) -> tuple[str, str, bool]:
    """(base frame field or 'kind', unit, categorical) for a colour-field name; KeyError if unknown."""
    if name == "kind":
        return "kind", "1", True
    if name not in colour_fields(src):
        raise KeyError(name)
    if name == "speed":
        return "velocity", src.unit("velocity"), False
    base = name
    if name not in src.field_names and name[-2:] in ("_x", "_y", "_z"):
        base = name[:-2]
    return base, src.unit(base), False


def scalar_field(src: FrameSource, name: str, i: int) -> np.ndarray:
    """Per-particle values of colour field ``name`` in frame ``i`` (N,)."""
    if name == "kind":
        return src.kind.astype(float)
    base, _, _ = resolve_field(src, name)
    arr = np.asarray(src.read(base, i), dtype=float)
    if name == "speed" or (name == base and arr.ndim == 2):
        return np.linalg.norm(arr, axis=1)
    if name != base:
        return arr[:, AXES.index(name[-1])]
    if arr.ndim != 1:
        raise KeyError(name)
    return arr


def kind_labels() -> dict[float, str]:
    return {float(k): v for k, v in KIND_NAMES.items()}
