"""HDF5 run file: writer and reader (format "taichi-sph", format_version 1).

Layout (the names are fixed, other tools read them):

- root attributes: ``format = "taichi-sph"``, ``format_version = 1``, ``mode``, ``dim``, ``dx``,
  ``code_version``, ``arch``, ``config_yaml`` and any extra scalar/string attributes.
- ``/particles/kind`` (N,) int8 (0 water, 1 wall, 2 soil, 3 air), ``/particles/id`` (N,).
- ``/markers/position`` (M, dim), ``/markers/porosity`` (M,), ``/markers/d50`` (M,) when given.
- ``/frames/time`` (F,) and ``/frames/<field>`` (F, N, ...), one chunk per frame, resizable along
  the frame axis, attribute ``units`` on each.  Boolean fields (``active``, ``free_surface``, ...) are
  stored as HDF5 booleans (h5py's enum of int8, FALSE = 0 / TRUE = 1: numpy bool in h5py, and 0 / 1
  to a reader that asks HDF5 for unsigned chars, as the XDMF sidecar does). Files written before
  held them as uint8 with attribute ``dtype = "bool"``; :class:`RunFile` reads both as bool.
- ``/diagnostics/<name>`` (S,) one row per step, attribute ``units``.
- ``/probes/<name>/time`` (k,) and ``/probes/<name>/value`` (k,) or (k, m), attribute ``units``.

The writer flushes after every frame, diagnostics block and probe block, and never marks the
file as "open for writing" in its superblock, so a process that is killed leaves every frame
written so far readable without repair tools.

This module imports numpy and h5py only (never a solver, never taichi).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path
from typing import Any, Iterable, Mapping

import h5py
import numpy as np

from ..kinds import KIND_NAMES

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "UNITS",
    "RunFile",
    "RunFileError",
    "RunWriter",
    "unit_for",
]

FORMAT = "taichi-sph"
FORMAT_VERSION = 1


#: Units of known field, diagnostic and probe names, for 3D runs.  Names whose unit depends on
#: the dimension (energies, volumes, masses: per metre of depth in 2D) are resolved by
#: :func:`unit_for`; names not listed here get ``"1"`` unless the caller passes a unit.
UNITS: dict[str, str] = {
    # particle state
    "position": "m",
    "velocity": "m/s",
    "darcy_velocity": "m/s",
    "acceleration": "m/s^2",
    "displacement": "m",
    "pressure": "Pa",
    "pore_pressure": "Pa",
    "excess_pore_pressure": "Pa",
    "density": "kg/m^3",
    "rho_bar": "kg/m^3",
    "reference_density": "kg/m^3",
    "porosity": "1",
    "saturation": "1",
    "d50": "m",
    "active": "1",
    "kind": "1",
    "id": "1",
    "free_surface": "1",
    "isolated": "1",
    "closed_bodies": "1",
    "shift_substeps": "1",
    "stress": "Pa",
    "effective_stress": "Pa",
    "deviatoric_stress": "Pa",
    "mean_stress": "Pa",
    "shear_stress": "Pa",
    "strain": "1",
    "plastic_strain": "1",
    "volumetric_strain": "1",
    "strain_rate": "1/s",
    "yielded": "1",
    "smoothing_length": "m",
    "temperature": "K",
    # per-step diagnostics
    "time": "s",
    "dt": "s",
    "step": "1",
    "kinetic_energy": "J",
    "potential_energy": "J",
    "total_energy": "J",
    "max_speed": "m/s",
    "max_velocity": "m/s",
    "max_acceleration": "m/s^2",
    "water_volume": "m^3",
    "soil_volume": "m^3",
    "air_volume": "m^3",
    "volume": "m^3",
    "mass": "kg",
    "water_mass": "kg",
    "cg_iterations": "1",
    "cg_residual": "1",
    "ppe_iterations": "1",
    "ppe_residual": "1",
    "wall_seconds": "s",
    "compile_seconds": "s",
    "n_active": "1",
    "n_removed": "1",
    "n_particles": "1",
    "n_neighbours_mean": "1",
    "n_neighbours_max": "1",
    "courant": "1",
    "density_error": "1",
    "mipps": "1e6 particle-steps/s",
    "drag_sum": "N",
    "drag_max": "N",
    # probes
    "water_level": "m",
    "head": "m",
    "discharge": "m^3/s",
    "flux": "m^3/s",
    "rho_w": "kg/m^3",
}

# Names whose unit loses one length dimension in 2D (quantities per metre of depth).
_PER_DEPTH_2D: dict[str, str] = {
    "J": "J/m",
    "m^3": "m^2",
    "kg": "kg/m",
    "N": "N/m",
    "m^3/s": "m^2/s",
}

# Prefixes of families of names (e.g. ``water_volume_layer``, ``kinetic_energy_water``).
_PREFIX_UNITS: tuple[tuple[str, str], ...] = (
    ("water_volume", "m^3"),
    ("soil_volume", "m^3"),
    ("air_volume", "m^3"),
    ("volume", "m^3"),
    ("kinetic_energy", "J"),
    ("potential_energy", "J"),
    ("pressure", "Pa"),
    ("pore_pressure", "Pa"),
    ("water_level", "m"),
    ("max_speed", "m/s"),
    ("discharge", "m^3/s"),
    ("wall_seconds", "s"),
    ("mass", "kg"),
)


def unit_for(name: str, dim: int = 3, units: Mapping[str, str] | None = None) -> str:
    """Unit string of a field/diagnostic/probe ``name`` in a ``dim``-dimensional run.

    ``units`` (caller-supplied, name -> unit) wins over the built-in table.  In 2D, energies,
    volumes, masses and discharges are per metre of depth (``"J/m"``, ``"m^2"``, ...).  Unknown
    names are dimensionless (``"1"``).
    """
    if units and name in units:
        return str(units[name])
    unit = UNITS.get(name)
    if unit is None:
        for prefix, u in _PREFIX_UNITS:
            if name.startswith(prefix):
                unit = u
                break
    if unit is None:
        return "1"
    if int(dim) == 2:
        unit = _PER_DEPTH_2D.get(unit, unit)
    return unit


class RunFileError(ValueError):
    """A path that is not a readable taichi-sph run file (missing, not HDF5, wrong format)."""


# --------------------------------------------------------------------------------------------
# helpers

# Library version bounds: 'v108' allows dense (large) attribute storage (config text) and keeps
# the superblock free of the "open for writing" flag that newer formats set, which would make a
# file left behind by a killed process unreadable without h5clear.
_LIBVER = ("v108", "v108")


def _attr_value(value: Any) -> Any:
    """Convert a Python value into something h5py stores as an attribute."""
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (dict, list, tuple)) and not (
        isinstance(value, (list, tuple)) and value and all(isinstance(v, (int, float)) for v in value)
    ):
        return json.dumps(value, default=str)
    if isinstance(value, (_dt.datetime, _dt.date)):
        return value.isoformat()
    return value


def _py(value: Any) -> Any:
    """numpy / bytes attribute value -> plain Python (JSON-friendly) value."""
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray):
        if value.ndim == 0:
            return _py(value[()])
        return [_py(v) for v in value.tolist()]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, (list, tuple)):
        return [_py(v) for v in value]
    return value


def _json_safe(value: Any) -> Any:
    """Replace non-finite floats by None so that strict JSON accepts the value."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def _check_name(name: str, what: str) -> None:
    if not isinstance(name, str) or not name or "/" in name or name in (".", ".."):
        raise ValueError(f"invalid {what} name {name!r}: a non-empty string without '/'")


def _storable(name: str, arr: Any) -> np.ndarray:
    """Array as stored in HDF5: numbers, or booleans (h5py writes them as HDF5 booleans)."""
    a = np.asarray(arr)
    if a.dtype.kind not in "biuf":
        raise ValueError(f"field {name!r}: unsupported dtype {a.dtype} (numbers or booleans only)")
    return a


def _append_rows(ds: h5py.Dataset, rows: np.ndarray) -> None:
    n0 = ds.shape[0]
    k = rows.shape[0]
    if k == 0:
        return
    ds.resize(n0 + k, axis=0)
    ds[n0 : n0 + k] = rows


def _create_growing(group: h5py.Group, name: str, row_shape: tuple[int, ...], dtype: Any,
                    chunk_rows: int, compression: str | None) -> h5py.Dataset:
    shape = (0, *row_shape)
    maxshape = (None, *row_shape)
    if all(s > 0 for s in row_shape):
        chunks: Any = (chunk_rows, *row_shape)
    else:
        chunks = True  # zero-sized rows: let h5py pick a valid chunk shape
    return group.create_dataset(name, shape=shape, maxshape=maxshape, chunks=chunks, dtype=dtype,
                                compression=compression)


# --------------------------------------------------------------------------------------------
# writer


class RunWriter:
    """Write one run file; a context manager.

    Parameters
    ----------
    path: file to create (parent directories are made; an existing file is replaced).
    mode, dim, dx, arch, config_yaml, code_version: root attributes (SPEC section 8).
    kind: (N,) particle kinds, stored as int8; ids: (N,) particle ids.
    markers: ``{"position": (M, dim), "porosity": (M,), "d50": (M,), ...}`` or None.
    attrs: extra root attributes (numbers, strings; dicts/lists are stored as JSON text).
    units: name -> unit overrides for frames, diagnostics and probes (see :func:`unit_for`).
    compression: h5py compression filter for frame datasets (None: uncompressed, fastest).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        mode: str,
        dim: int,
        dx: float,
        arch: str,
        config_yaml: str,
        kind: np.ndarray,
        ids: np.ndarray,
        code_version: str,
        markers: Mapping[str, np.ndarray] | None = None,
        attrs: Mapping[str, Any] | None = None,
        units: Mapping[str, str] | None = None,
        compression: str | None = None,
    ) -> None:
        dim = int(dim)
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        kind_arr = np.asarray(kind)
        ids_arr = np.asarray(ids)
        if kind_arr.ndim != 1:
            raise ValueError(f"kind must be a 1D array (N,), got shape {kind_arr.shape}")
        if ids_arr.shape != kind_arr.shape:
            raise ValueError(f"ids shape {ids_arr.shape} differs from kind shape {kind_arr.shape}")
        self.path = Path(path)
        self.dim = dim
        self.n_particles = int(kind_arr.shape[0])
        self.units: dict[str, str] = dict(units or {})
        self.compression = compression
        self._frame_names: tuple[str, ...] | None = None
        self._diag_names: tuple[str, ...] | None = None
        self._n_frames = 0
        self._file: h5py.File | None = None

        self.path.parent.mkdir(parents=True, exist_ok=True)
        f = h5py.File(self.path, "w", libver=_LIBVER)
        self._file = f
        try:
            a = f.attrs
            a["format"] = FORMAT
            a["format_version"] = np.int64(FORMAT_VERSION)
            a["mode"] = str(mode)
            a["dim"] = np.int64(dim)
            a["dx"] = np.float64(dx)
            a["code_version"] = str(code_version)
            a["arch"] = str(arch)
            a["config_yaml"] = str(config_yaml)
            a["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
            for k, v in (attrs or {}).items():
                if v is not None:
                    a[str(k)] = _attr_value(v)

            p = f.create_group("particles")
            dk = p.create_dataset("kind", data=kind_arr.astype(np.int8))
            dk.attrs["units"] = "1"
            dk.attrs["names"] = json.dumps({str(k): v for k, v in KIND_NAMES.items()})
            di = p.create_dataset("id", data=ids_arr)
            di.attrs["units"] = "1"

            if markers is not None:
                self._write_markers(f, markers)
            f.create_group("frames")
            f.create_group("diagnostics")
            f.create_group("probes")
            f.flush()
        except BaseException:
            f.close()
            self._file = None
            raise

    @classmethod
    def reopen(cls, path: str | Path, *, n_frames: int, n_diagnostics: int, probe_samples: Mapping[str, int],
               units: Mapping[str, str] | None = None, compression: str | None = None) -> "RunWriter":
        """Open an existing run file to continue it (resume from a checkpoint). What was written after
        the checkpoint is cut away first: frames past `n_frames`, diagnostic rows past `n_diagnostics`,
        probe samples past ``probe_samples[name]`` (probes not named there are removed)."""
        self = cls.__new__(cls)
        self.path = Path(path)
        f = h5py.File(self.path, "r+", libver=_LIBVER)
        self._file = f
        try:
            self.dim = int(f.attrs["dim"])
            self.n_particles = int(f["particles/kind"].shape[0])
            self.units = dict(units or {})
            self.compression = compression
            frames = f.require_group("frames")
            names = tuple(k for k in frames.keys() if k != "time")
            for name in (*names, "time"):
                if name in frames and frames[name].shape[0] > n_frames:
                    frames[name].resize(n_frames, axis=0)
            self._frame_names = names or None
            self._n_frames = int(n_frames) if names else 0
            diag = f.require_group("diagnostics")
            for name in diag.keys():
                if diag[name].shape[0] > n_diagnostics:
                    diag[name].resize(n_diagnostics, axis=0)
            self._diag_names = tuple(diag.keys()) or None
            probes = f.require_group("probes")
            for name in list(probes.keys()):
                keep = probe_samples.get(name)
                if keep is None:
                    del probes[name]
                    continue
                for part in ("time", "value"):
                    if probes[name][part].shape[0] > keep:
                        probes[name][part].resize(keep, axis=0)
            f.flush()
        except BaseException:
            f.close()
            self._file = None
            raise
        return self

    # -- context manager ----------------------------------------------------------------------
    def __enter__(self) -> "RunWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    # -- properties ---------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._file is None

    @property
    def n_frames(self) -> int:
        return self._n_frames

    @property
    def file(self) -> h5py.File:
        """The open h5py file (for additions outside the fixed layout)."""
        return self._require_open()

    def _require_open(self) -> h5py.File:
        if self._file is None:
            raise ValueError(f"{self.path}: run file is closed")
        return self._file

    def _unit(self, name: str) -> str:
        return unit_for(name, self.dim, self.units)

    # -- markers ------------------------------------------------------------------------------
    def _write_markers(self, f: h5py.File, markers: Mapping[str, np.ndarray]) -> None:
        if "position" not in markers:
            raise ValueError("markers must contain 'position' (M, dim)")
        pos = np.asarray(markers["position"], dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != self.dim:
            raise ValueError(f"markers 'position' must have shape (M, {self.dim}), got {pos.shape}")
        m = pos.shape[0]
        g = f.create_group("markers")
        for name, arr in markers.items():
            _check_name(name, "marker")
            a = _storable(f"markers/{name}", arr)
            if a.ndim == 0 or a.shape[0] != m:
                raise ValueError(f"markers {name!r}: first dimension must be M = {m}, got shape {a.shape}")
            ds = g.create_dataset(name, data=a)
            ds.attrs["units"] = self._unit(name)

    # -- frames -------------------------------------------------------------------------------
    def write_frame(self, time: float, fields: Mapping[str, np.ndarray]) -> int:
        """Append one frame; returns its index.  Every call must pass the same field names."""
        f = self._require_open()
        if "time" in fields:
            raise ValueError("field 'time' is reserved (pass the time as the first argument)")
        names = tuple(fields)
        if self._frame_names is None:
            if not names:
                raise ValueError("write_frame needs at least one field")
            for name in names:
                _check_name(name, "field")
        else:
            expected = set(self._frame_names)
            got = set(names)
            if got != expected:
                missing = sorted(expected - got)
                extra = sorted(got - expected)
                parts = []
                if missing:
                    parts.append(f"missing field {', '.join(map(repr, missing))}")
                if extra:
                    parts.append(f"unexpected field {', '.join(map(repr, extra))}")
                raise ValueError(
                    f"write_frame: fields differ from the first frame ({'; '.join(parts)}); "
                    f"expected {sorted(expected)}"
                )

        # validate everything before touching the file, so a bad call leaves no partial frame
        data: dict[str, np.ndarray] = {}
        for name in names:
            a = _storable(name, fields[name])
            if a.ndim == 0 or a.shape[0] != self.n_particles:
                raise ValueError(
                    f"field {name!r}: first dimension must be N = {self.n_particles}, got shape {a.shape}"
                )
            if name == "position" and a.shape[1:] != (self.dim,):
                raise ValueError(f"field 'position' must have shape (N, {self.dim}), got {a.shape}")
            if self._frame_names is not None:
                ds = f["frames"][name]
                if a.shape != ds.shape[1:]:
                    raise ValueError(
                        f"field {name!r}: shape {a.shape} differs from the first frame {ds.shape[1:]}"
                    )
            data[name] = a

        g = f["frames"]
        if self._frame_names is None:
            for name, a in data.items():
                ds = _create_growing(g, name, a.shape, a.dtype, 1, self.compression)
                ds.attrs["units"] = self._unit(name)
            dt_ = _create_growing(g, "time", (), np.float64, 1024, None)
            dt_.attrs["units"] = "s"
            self._frame_names = names

        i = self._n_frames
        for name, a in data.items():
            ds = g[name]
            if a.dtype == np.bool_ and ds.dtype != np.bool_:  # a file of an earlier version resumed: uint8
                a = a.astype(ds.dtype)
            _append_rows(ds, a[None, ...])
        # time last: a frame counts once its time is written
        _append_rows(g["time"], np.asarray([float(time)], dtype=np.float64))
        self._n_frames = i + 1
        f.flush()
        return i

    # -- diagnostics --------------------------------------------------------------------------
    def append_diagnostics(self, columns: Mapping[str, Any], units: Mapping[str, str] | None = None) -> None:
        """Append per-step rows to ``/diagnostics/<name>``.

        All columns must have the same length, and every call the same names as the first.
        ``units`` overrides the units of these names (applied when the datasets are created).
        """
        f = self._require_open()
        if not columns:
            return
        names = tuple(columns)
        arrays: dict[str, np.ndarray] = {}
        length: int | None = None
        for name in names:
            _check_name(name, "diagnostics column")
            a = _storable(name, np.atleast_1d(np.asarray(columns[name])))
            if a.ndim != 1:
                raise ValueError(f"diagnostics column {name!r}: must be 1D, got shape {a.shape}")
            if length is None:
                length = a.shape[0]
            elif a.shape[0] != length:
                raise ValueError(
                    f"diagnostics column {name!r} has {a.shape[0]} rows, expected {length} "
                    f"(as column {names[0]!r})"
                )
            arrays[name] = a
        if self._diag_names is not None and set(names) != set(self._diag_names):
            diff = sorted(set(names) ^ set(self._diag_names))
            raise ValueError(
                f"append_diagnostics: columns differ from the first call (column {diff[0]!r}); "
                f"expected {sorted(self._diag_names)}"
            )
        g = f["diagnostics"]
        if self._diag_names is None:
            for name, a in arrays.items():
                ds = _create_growing(g, name, (), a.dtype, 4096, None)
                ds.attrs["units"] = (units or {}).get(name) or self._unit(name)
            self._diag_names = names
        for name, a in arrays.items():
            ds = g[name]
            _append_rows(ds, a.astype(ds.dtype, copy=False))
        f.flush()

    # -- probes -------------------------------------------------------------------------------
    def append_probe(self, name: str, times: Any, values: Any, units: str | None = None,
                     attrs: Mapping[str, Any] | None = None) -> None:
        """Append samples to ``/probes/<name>/time`` and ``/probes/<name>/value``.

        ``values`` is (k,) or (k, m); ``units`` is the unit of ``value`` (default from the name);
        ``attrs`` (e.g. probe location, kind) are stored on the probe group.
        """
        f = self._require_open()
        _check_name(name, "probe")
        t = np.atleast_1d(np.asarray(times, dtype=np.float64))
        v = _storable(name, np.asarray(values))
        if v.ndim == 0:
            v = v.reshape(1)
        if t.ndim != 1:
            raise ValueError(f"probe {name!r}: times must be 1D, got shape {t.shape}")
        if v.ndim not in (1, 2) or v.shape[0] != t.shape[0]:
            raise ValueError(
                f"probe {name!r}: values must be (k,) or (k, m) with k = {t.shape[0]}, got shape {v.shape}"
            )
        pg = f["probes"]
        if name not in pg:
            g = pg.create_group(name)
            dt_ = _create_growing(g, "time", (), np.float64, 1024, None)
            dt_.attrs["units"] = "s"
            dv = _create_growing(g, "value", v.shape[1:], v.dtype if v.dtype.kind == "f" else np.float64,
                                 1024, None)
            dv.attrs["units"] = units if units is not None else self._unit(name)
        else:
            g = pg[name]
            if v.shape[1:] != g["value"].shape[1:]:
                raise ValueError(
                    f"probe {name!r}: value shape {v.shape[1:]} per sample differs from earlier "
                    f"{g['value'].shape[1:]}"
                )
            if units is not None and g["value"].attrs.get("units") != units:
                g["value"].attrs["units"] = units
        for k, val in (attrs or {}).items():
            if val is not None:
                g.attrs[str(k)] = _attr_value(val)
        _append_rows(g["time"], t)
        _append_rows(g["value"], v.astype(g["value"].dtype, copy=False))
        f.flush()

    # -- attributes ---------------------------------------------------------------------------
    def set_attrs(self, **kw: Any) -> None:
        """Set (or, with value None, delete) root attributes, e.g. status, exit_reason, mipps."""
        f = self._require_open()
        for k, v in kw.items():
            if v is None:
                if k in f.attrs:
                    del f.attrs[k]
            else:
                f.attrs[k] = _attr_value(v)
        f.flush()

    def flush(self) -> None:
        self._require_open().flush()

    def close(self) -> None:
        """Close the file; calling it again does nothing."""
        f = self._file
        if f is None:
            return
        self._file = None
        try:
            if f.id.valid:
                f.flush()
        finally:
            f.close()


# --------------------------------------------------------------------------------------------
# reader


def _is_bool(ds: h5py.Dataset) -> bool:
    """An HDF5 boolean (numpy bool in h5py), or the uint8 with attribute dtype = "bool" of earlier files."""
    return ds.dtype == np.bool_ or ds.attrs.get("dtype") in ("bool", b"bool")


def _read(ds: h5py.Dataset, sel: Any = ()) -> np.ndarray:
    a = np.asarray(ds[sel])
    if a.dtype != np.bool_ and _is_bool(ds):
        a = a.astype(bool)
    return a


class RunFile:
    """Read a run file (read-only); a context manager.

    Raises :class:`RunFileError` if the file is missing, is not HDF5, or is not a taichi-sph run.
    The file is opened without HDF5 file locking, so a run that is still being written can be
    inspected.
    """

    _STANDARD_ATTRS = frozenset(
        {"format", "format_version", "mode", "dim", "dx", "code_version", "arch", "config_yaml"}
    )

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise RunFileError(f"{self.path}: no such run file")
        if not self.path.is_file():
            raise RunFileError(f"{self.path}: not a file")
        try:
            is_hdf5 = h5py.is_hdf5(self.path)
        except OSError:
            is_hdf5 = False
        if not is_hdf5:
            raise RunFileError(f"{self.path}: not an HDF5 file")
        try:
            try:
                self._f = h5py.File(self.path, "r", locking=False)
            except (TypeError, ValueError, OSError):
                # no locking option in this h5py/HDF5, or the file is already open in this
                # process with other locking flags: open with the defaults
                self._f = h5py.File(self.path, "r")
        except OSError as e:
            msg = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise RunFileError(f"{self.path}: cannot open HDF5 file ({msg})") from None
        fmt = _py(self._f.attrs.get("format"))
        if fmt != FORMAT:
            self._f.close()
            found = "no 'format' attribute" if fmt is None else f"format {fmt!r}"
            raise RunFileError(f"{self.path}: not a taichi-sph run file ({found})")

    # -- context manager ----------------------------------------------------------------------
    def __enter__(self) -> "RunFile":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def close(self) -> None:
        f = getattr(self, "_f", None)
        if f is not None and f.id.valid:
            f.close()

    def __repr__(self) -> str:
        return f"RunFile({str(self.path)!r})"

    @property
    def h5(self) -> h5py.File:
        """The underlying read-only h5py file."""
        return self._f

    # -- root attributes ----------------------------------------------------------------------
    @property
    def attrs(self) -> dict[str, Any]:
        return {k: _py(v) for k, v in self._f.attrs.items()}

    @property
    def mode(self) -> str:
        return str(_py(self._f.attrs.get("mode", "")))

    @property
    def dim(self) -> int:
        return int(self._f.attrs["dim"])

    @property
    def dx(self) -> float:
        return float(self._f.attrs["dx"])

    @property
    def format_version(self) -> int:
        return int(self._f.attrs.get("format_version", 0))

    @property
    def config_yaml(self) -> str:
        return str(_py(self._f.attrs.get("config_yaml", "")))

    # -- particles ----------------------------------------------------------------------------
    @property
    def kind(self) -> np.ndarray:
        return np.asarray(self._f["particles/kind"][()], dtype=np.int8)

    @property
    def ids(self) -> np.ndarray:
        return np.asarray(self._f["particles/id"][()])

    @property
    def n_particles(self) -> int:
        return int(self._f["particles/kind"].shape[0])

    # -- frames -------------------------------------------------------------------------------
    def _frames(self) -> h5py.Group | None:
        return self._f.get("frames")

    @property
    def field_names(self) -> list[str]:
        g = self._frames()
        if g is None:
            return []
        return [k for k in g.keys() if k != "time" and isinstance(g[k], h5py.Dataset)]

    @property
    def n_frames(self) -> int:
        g = self._frames()
        if g is None or "time" not in g:
            return 0
        n = int(g["time"].shape[0])
        for name in self.field_names:  # a frame counts only when every field holds it
            n = min(n, int(g[name].shape[0]))
        return n

    @property
    def times(self) -> np.ndarray:
        n = self.n_frames
        if n == 0:
            return np.zeros(0, dtype=np.float64)
        return np.asarray(self._frames()["time"][:n], dtype=np.float64)

    @property
    def units(self) -> dict[str, str]:
        """Units of the frame fields (and ``time``)."""
        g = self._frames()
        if g is None:
            return {}
        return {k: str(_py(g[k].attrs.get("units", "1"))) for k in g.keys()}

    def _index(self, i: int) -> int:
        n = self.n_frames
        j = int(i)
        if j < 0:
            j += n
        if not 0 <= j < n:
            raise IndexError(f"{self.path}: frame {i} out of range ({n} frames)")
        return j

    def frame(self, i: int) -> dict[str, np.ndarray]:
        """All fields of frame ``i`` (negative counts from the end), plus ``time`` (0-d array)."""
        j = self._index(i)
        g = self._frames()
        out = {"time": np.asarray(g["time"][j])}
        for name in self.field_names:
            out[name] = _read(g[name], j)
        return out

    def field(self, name: str, i: int) -> np.ndarray:
        g = self._frames()
        if g is None or name not in g or name == "time":
            raise KeyError(f"{self.path}: no frame field {name!r} (have {self.field_names})")
        return _read(g[name], self._index(i))

    # -- diagnostics, probes, markers ---------------------------------------------------------
    def diagnostics(self) -> dict[str, np.ndarray]:
        g = self._f.get("diagnostics")
        if g is None:
            return {}
        return {k: _read(g[k]) for k in g.keys() if isinstance(g[k], h5py.Dataset)}

    def diagnostics_units(self) -> dict[str, str]:
        g = self._f.get("diagnostics")
        if g is None:
            return {}
        return {k: str(_py(g[k].attrs.get("units", "1"))) for k in g.keys()}

    def probes(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        g = self._f.get("probes")
        if g is None:
            return {}
        out = {}
        for name in g.keys():
            pg = g[name]
            if isinstance(pg, h5py.Group) and "time" in pg and "value" in pg:
                t = np.asarray(pg["time"][()])
                v = _read(pg["value"])
                k = min(t.shape[0], v.shape[0])
                out[name] = (t[:k], v[:k])
        return out

    def probe_units(self) -> dict[str, str]:
        g = self._f.get("probes")
        if g is None:
            return {}
        return {
            name: str(_py(g[name]["value"].attrs.get("units", "1")))
            for name in g.keys()
            if isinstance(g[name], h5py.Group) and "value" in g[name]
        }

    def markers(self) -> dict[str, np.ndarray] | None:
        g = self._f.get("markers")
        if g is None:
            return None
        return {k: _read(g[k]) for k in g.keys() if isinstance(g[k], h5py.Dataset)}

    # -- summary ------------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """What the file holds, as a JSON-serialisable dict (non-finite numbers become None)."""
        a = self.attrs
        kind = self.kind
        counts: dict[str, int] = {"total": int(kind.shape[0])}
        for code, name in KIND_NAMES.items():
            counts[name] = int(np.count_nonzero(kind == code))
        for code in sorted(set(np.unique(kind).tolist()) - set(KIND_NAMES)):
            counts[f"kind_{int(code)}"] = int(np.count_nonzero(kind == code))

        n = self.n_frames
        times = self.times
        g = self._frames()
        frames: dict[str, Any] = {}
        for name in self.field_names:
            ds = g[name]
            frames[name] = {
                "shape": [n, *map(int, ds.shape[1:])],
                "units": str(_py(ds.attrs.get("units", "1"))),
                "dtype": "bool" if _is_bool(ds) else str(ds.dtype),
            }

        diag = self.diagnostics()
        dunits = self.diagnostics_units()
        diagnostics: dict[str, Any] = {
            "n_steps": int(max((v.shape[0] for v in diag.values()), default=0)),
            "columns": {
                k: {"units": dunits.get(k, "1"), "last": (_py(v[-1]) if v.shape[0] else None)}
                for k, v in diag.items()
            },
        }
        if "wall_seconds" in diag and diag["wall_seconds"].size:
            diagnostics["wall_seconds_total"] = float(np.sum(diag["wall_seconds"]))
        if "cg_iterations" in diag and diag["cg_iterations"].size:
            it = diag["cg_iterations"].astype(np.float64)
            diagnostics["cg_iterations_mean"] = float(np.mean(it))
            diagnostics["cg_iterations_max"] = float(np.max(it))
        if "time" in diag and diag["time"].size:
            diagnostics["time_range"] = [float(diag["time"][0]), float(diag["time"][-1])]

        probes = self.probes()
        punits = self.probe_units()
        probe_info = {
            name: {"samples": int(t.shape[0]), "units": punits.get(name, "1"),
                   "value_shape": [int(s) for s in v.shape[1:]]}
            for name, (t, v) in probes.items()
        }

        markers = self.markers()
        extra = {k: v for k, v in a.items() if k not in self._STANDARD_ATTRS}

        out = {
            "file": str(self.path),
            "format": a.get("format"),
            "format_version": a.get("format_version"),
            "mode": a.get("mode"),
            "dim": a.get("dim"),
            "dx": a.get("dx"),
            "arch": a.get("arch"),
            "code_version": a.get("code_version"),
            "n_particles": counts,
            "n_frames": n,
            "time_range": [float(times[0]), float(times[-1])] if n else None,
            "frames": frames,
            "diagnostics": diagnostics,
            "probes": probe_info,
            "markers": int(markers["position"].shape[0]) if markers and "position" in markers else 0,
            "attrs": extra,
        }
        return _json_safe(out)


def iter_frames(run: RunFile, indices: Iterable[int] | None = None):
    """Yield ``(index, frame dict)`` for the given frame indices (default: all)."""
    for i in (range(run.n_frames) if indices is None else indices):
        yield i, run.frame(i)
