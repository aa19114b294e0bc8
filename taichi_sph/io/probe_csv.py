"""``<run>.probes.csv``: every probe sample of a run as one comma-separated table.

One header line ``time,<column>,...`` (a probe's name, or ``<name>_x``, ``<name>_y``[, ``<name>_z``]
for a velocity probe), then one row per sampling time in time order. A probe that was not sampled
at a row's time leaves its cell empty (read as NaN). Numbers are written with Python's shortest
round-trip repr, so they equal the HDF5 values bit for bit. Load it with
``numpy.genfromtxt(path, delimiter=",", names=True)`` or ``pandas.read_csv(path)``.

Rows are flushed with each block of frames, so a killed run leaves a readable file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

__all__ = ["ProbeCSVWriter", "probe_csv_path"]


def probe_csv_path(h5_path: str | Path) -> Path:
    """``<run>.probes.csv`` beside ``<run>.h5``."""
    return Path(h5_path).with_suffix(".probes.csv")


class ProbeCSVWriter:
    """Writes the table; with `keep_rows` (a resumed run) the first `keep_rows` rows of the existing
    file are kept and the rest is cut away. `rows` counts the rows the file holds."""

    def __init__(self, path: str | Path, columns: Sequence[str], keep_rows: int | None = None):
        self.path = Path(path)
        self.columns = list(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        kept: list[str] = []
        if keep_rows is not None and self.path.is_file():
            kept = self.path.read_text(encoding="ascii").splitlines(keepends=True)[1 : 1 + int(keep_rows)]
        self._f = open(self.path, "w", encoding="ascii", newline="")  # noqa: SIM115  (closed by close())
        self._f.write(",".join(["time", *self.columns]) + "\n")
        self._f.writelines(kept)
        self.rows = len(kept)
        self._f.flush()

    def append(self, time: float, values: Mapping[str, float]) -> None:
        """One row at ``time``; columns missing from ``values`` stay empty."""
        unknown = set(values) - set(self.columns)
        if unknown:
            raise ValueError(f"{self.path}: unknown probe column {min(unknown)!r}")
        cells = [repr(float(time))] + [repr(float(values[c])) if c in values else "" for c in self.columns]
        self._f.write(",".join(cells) + "\n")
        self.rows += 1

    def flush(self) -> None:
        if not self._f.closed:
            self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()
