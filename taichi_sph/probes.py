"""Probes (gauges): pressure at a point, water level on a vertical line, water volume and mean
velocity in a box, evaluated from host (numpy) particle arrays, so one implementation serves every
solver mode. The run loop fetches the arrays only at steps where some probe is due.

Particle arrays (a mapping, particles in any consistent order):

- ``position`` (N, dim) m, ``velocity`` (N, dim) m/s, ``pressure`` (N,) Pa, ``kind`` (N,) (0 water,
  1 wall), ``active`` (N,) bool;
- ``volume`` (N,) m^dim: the bulk volume a particle stands for, m_j / rho_bar_j with
  rho_bar = eps rho_w (seed 000 eq 33), so dx^dim in free water and for walls;
- ``porosity`` (N,) optional (1 when absent): a water particle holds eps_j volume_j of water.

Each quantity uses the cubic-spline kernel of the solver (support 2.4 dx, h = 1.2 dx):

- pressure (Pa): Shepard-normalised SPH interpolation over water particles (seed 000 eq 10 with
  the kernel sum in the denominator), P(x) = sum_j P_j V_j W(x - x_j) / sum_j V_j W(x - x_j).
  Reproduces a linear pressure field within 1e-3 rho g dx when the support is full of water;
  within 2.4 dx of a wall it is a one-sided average (a gauge on a floor reads the pressure about
  0.6 dx up in the water).
  A dry gauge (water fraction below 0.1 at the point) reads 0, the atmosphere.
- water_level (m): elevation where the SPH water fraction phi(z) = sum_water V_j W / (1 - s_wall),
  s_wall = sum_wall V_j W, falls through 0.5 on the line, found from the top down on samples dz =
  dx / 4 apart and linearly interpolated. Dividing by the kernel volume not taken by walls keeps
  the fraction right next to walls and over obstacles; points inside solids count as full. Chosen
  over "the highest water particle in a tube" because that reading sits dx / 2 below a flat
  surface, jumps by whole particle layers and follows single splash droplets (one particle alone
  makes phi at most 0.32 in 2D, 0.18 in 3D, so droplets never count). A dry line reads its bottom.
- water_volume (m^3, m^2 per metre in 2D): sum of eps_j V_j over active water particles inside the
  box (each holds m / rho_w of water).
- velocity (m/s, dim components): volume-weighted mean velocity of the active water particles in
  the box (in mode isph the Darcy velocity vD of the frames); NaN when the box holds no water.
- soil_level (m, mode wcsph_biot): the mean over the box's columns (dx wide, from its low corner) of
  the top of the soil in the column, the highest soil particle inside the box plus dx / 2 (a flat
  surface reads its true height); a column without soil reads the box's bottom. A crest's height
  (erosion) or a sand surface's uplift (heave).
- plastic_strain (1, mode wcsph_biot): the largest accumulated plastic shear strain of the soil
  particles inside the box; 0 when none is there (yield onset at a toe: metric first_above).
- water_depth (m): water standing on the ground at a point's column, the water level on the vertical
  line from `point` less the soil top in that column (as soil_level, for a column dx wide), 0 when
  the water surface is at or below it (flow over a crest).
- water_front (m): the largest x of the active water particles inside the box, the box's low x when it
  holds none. A wetting front's foot in a levee (a box along the floor, one and a half spacings high):
  the farthest pore water, as `failure.wetting_front` reads it from the frames. It follows single
  particles; docs/levee.md says how far a front's tip scatters.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .sph.kernels import SUPPORT_FACTOR, w_np

WATER, WALL, SOIL = 0, 1, 2

#: water fraction below which a pressure gauge is dry and reads 0 Pa
DRY_FRACTION = 0.1
#: water fraction that marks the free surface on a water-level line
SURFACE_FRACTION = 0.5
#: kernel volume left by walls below which a sample point counts as inside a solid
SOLID_FREE_FRACTION = 0.25

_UNITS = {"pressure": "Pa", "water_level": "m", "water_volume": "m^3", "velocity": "m/s", "soil_level": "m",
          "plastic_strain": "1", "water_depth": "m", "water_front": "m"}


def probe_unit(kind: str, dim: int) -> str:
    """Unit of a probe type's value (volumes per metre of depth in 2D)."""
    unit = _UNITS[kind]
    return "m^2" if (unit == "m^3" and dim == 2) else unit


def _water(arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    return (np.asarray(arrays["kind"]) == WATER) & np.asarray(arrays["active"], dtype=bool)


def _kernel_sums(points: np.ndarray, pos: np.ndarray, weights: np.ndarray, dx: float, dim: int,
                 values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each point: sum_j weights_j W(|x - x_j|) and sum_j weights_j values_j W (cKDTree pairs)."""
    from scipy.spatial import cKDTree

    n = points.shape[0]
    if pos.shape[0] == 0:
        return np.zeros(n), np.zeros(n)
    r_e = SUPPORT_FACTOR * dx
    h = 0.5 * r_e
    pairs = cKDTree(points).sparse_distance_matrix(cKDTree(pos), r_e, output_type="ndarray")
    rows, cols, dist = pairs["i"], pairs["j"], pairs["v"]
    wv = w_np(dist, h, dim) * weights[cols]
    s = np.bincount(rows, weights=wv, minlength=n)
    sv = np.bincount(rows, weights=wv * values[cols], minlength=n) if values is not None else np.zeros(n)
    return s, sv


def pressure_at(point: Sequence[float], arrays: Mapping[str, np.ndarray], dx: float) -> float:
    """Shepard-interpolated water pressure at ``point`` (Pa); 0 where the point is dry."""
    pos = np.asarray(arrays["position"], dtype=float)
    dim = pos.shape[1]
    water = _water(arrays)
    x = np.asarray(point, dtype=float).reshape(1, dim)
    near = water & (np.sum((pos - x) ** 2, axis=1) < (SUPPORT_FACTOR * dx) ** 2)
    vol = np.asarray(arrays["volume"], dtype=float)[near]
    p = np.asarray(arrays["pressure"], dtype=float)[near]
    s, sp = _kernel_sums(x, pos[near], vol, dx, dim, p)
    if s[0] < DRY_FRACTION:
        return 0.0
    return float(sp[0] / s[0])


def water_fraction_on_line(point: Sequence[float], arrays: Mapping[str, np.ndarray], dx: float,
                           top: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Samples z (dz = dx / 4) from ``point``'s height up to ``top`` and the water fraction phi(z)
    on the vertical line through ``point`` (points inside solids get phi = 1)."""
    pos = np.asarray(arrays["position"], dtype=float)
    dim = pos.shape[1]
    active = np.asarray(arrays["active"], dtype=bool)
    kind = np.asarray(arrays["kind"])
    vol = np.asarray(arrays["volume"], dtype=float)
    p = np.asarray(point, dtype=float)
    r_e = SUPPORT_FACTOR * dx
    if top is None:
        top = float(pos[active, -1].max()) + r_e if active.any() else p[-1]
    n = max(math.ceil((top - p[-1]) / (0.25 * dx)), 0) + 1
    z = p[-1] + 0.25 * dx * np.arange(n)
    samples = np.repeat(p.reshape(1, dim), n, axis=0)
    samples[:, -1] = z
    tube = active & (np.sum((pos[:, :-1] - p[:-1]) ** 2, axis=1) < r_e * r_e)
    water = tube & (kind == WATER)
    wall = tube & (kind == WALL)
    s_water, _ = _kernel_sums(samples, pos[water], vol[water], dx, dim)
    s_wall, _ = _kernel_sums(samples, pos[wall], vol[wall], dx, dim)
    free = 1.0 - s_wall
    solid = free < SOLID_FREE_FRACTION
    phi = np.where(solid, 1.0, s_water / np.maximum(free, SOLID_FREE_FRACTION))
    return z, phi


def water_level(point: Sequence[float], arrays: Mapping[str, np.ndarray], dx: float,
                top: float | None = None) -> float:
    """Elevation (m) where the water fraction falls through 0.5, searched from the top down on the
    vertical line rising from ``point``; the line's bottom when it is dry."""
    z, phi = water_fraction_on_line(point, arrays, dx, top)
    wet = np.flatnonzero(phi >= SURFACE_FRACTION)
    if wet.size == 0:
        return float(z[0])
    k = int(wet[-1])
    if k == z.size - 1:
        return float(z[k])
    f0, f1 = phi[k], phi[k + 1]
    return float(z[k] + (f0 - SURFACE_FRACTION) / (f0 - f1) * (z[k + 1] - z[k]))


def surge_front(point: Sequence[float], arrays: Mapping[str, np.ndarray], dx: float,
                end: float | None = None) -> float:
    """Front of a body of water running along +x (m): the last x at which the water fraction phi (as
    for ``water_level``, wall-corrected) falls through 0.5 on the horizontal line from ``point`` to
    ``end`` (default: the furthest water particle plus a kernel support), samples dx / 4 apart.

    This is the edge of the SPH water body, the same surface criterion as the level gauge: a
    column face on the lattice reads its true position (the leading particle centre lies dx / 2
    behind it), and a lone droplet never counts (phi <= 0.32 in 2D). A dry line reads its start.
    For a surge on a floor take ``point`` at the height dx / 2 of the first particle layer."""
    pos = np.asarray(arrays["position"], dtype=float)
    dim = pos.shape[1]
    active = np.asarray(arrays["active"], dtype=bool)
    kind = np.asarray(arrays["kind"])
    vol = np.asarray(arrays["volume"], dtype=float)
    p = np.asarray(point, dtype=float)
    r_e = SUPPORT_FACTOR * dx
    water = active & (kind == WATER)
    if end is None:
        end = float(pos[water, 0].max()) + r_e if water.any() else p[0]
    n = max(math.ceil((end - p[0]) / (0.25 * dx)), 0) + 1
    samples = np.repeat(p.reshape(1, dim), n, axis=0)
    samples[:, 0] = p[0] + 0.25 * dx * np.arange(n)
    off = np.delete(pos - p, 0, axis=1)  # distance from the line
    near = active & (np.sum(off * off, axis=1) < r_e * r_e)
    wall = near & (kind == WALL)
    s_water, _ = _kernel_sums(samples, pos[near & water], vol[near & water], dx, dim)
    s_wall, _ = _kernel_sums(samples, pos[wall], vol[wall], dx, dim)
    free = 1.0 - s_wall
    phi = np.where(free < SOLID_FREE_FRACTION, 1.0, s_water / np.maximum(free, SOLID_FREE_FRACTION))
    wet = np.flatnonzero(phi >= SURFACE_FRACTION)
    x = samples[:, 0]
    if wet.size == 0:
        return float(x[0])
    k = int(wet[-1])
    if k == n - 1:
        return float(x[k])
    f0, f1 = phi[k], phi[k + 1]
    return float(x[k] + (f0 - SURFACE_FRACTION) / (f0 - f1) * (x[k + 1] - x[k]))


def _in_box(pos: np.ndarray, lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    return np.all((pos >= np.asarray(lo, dtype=float)) & (pos <= np.asarray(hi, dtype=float)), axis=1)


def water_volume_in_box(lo: Sequence[float], hi: Sequence[float], arrays: Mapping[str, np.ndarray]) -> float:
    """Water held by the active water particles inside the box (m^3; m^2 per metre in 2D)."""
    pos = np.asarray(arrays["position"], dtype=float)
    sel = _water(arrays) & _in_box(pos, lo, hi)
    vol = np.asarray(arrays["volume"], dtype=float)[sel]
    eps = arrays.get("porosity")
    if eps is not None:
        vol = vol * np.asarray(eps, dtype=float)[sel]
    return float(vol.sum())


def mean_velocity_in_box(lo: Sequence[float], hi: Sequence[float], arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    """Volume-weighted mean velocity of the water in the box (m/s); NaN when it holds none."""
    pos = np.asarray(arrays["position"], dtype=float)
    sel = _water(arrays) & _in_box(pos, lo, hi)
    vol = np.asarray(arrays["volume"], dtype=float)[sel]
    if vol.sum() <= 0:
        return np.full(pos.shape[1], np.nan)
    vel = np.asarray(arrays["velocity"], dtype=float)[sel]
    return (vel * vol[:, None]).sum(axis=0) / vol.sum()


def _soil(arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    return (np.asarray(arrays["kind"]) == SOIL) & np.asarray(arrays["active"], dtype=bool)


def soil_level_in_box(lo: Sequence[float], hi: Sequence[float], arrays: Mapping[str, np.ndarray],
                      dx: float) -> float:
    """Mean soil top (m) over the box's columns: in each column dx wide (per horizontal axis, from the
    low corner) the highest soil particle inside the box plus dx / 2, or the box's bottom without one."""
    pos = np.asarray(arrays["position"], dtype=float)
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    sel = _soil(arrays) & _in_box(pos, lo, hi)
    counts = np.maximum(np.ceil((hi[:-1] - lo[:-1]) / dx - 1e-9).astype(int), 1)
    top = np.full(counts, lo[-1])
    if sel.any():
        cell = np.minimum(((pos[sel, :-1] - lo[:-1]) / dx).astype(int), counts - 1)
        z = np.minimum(pos[sel, -1] + 0.5 * dx, hi[-1])
        np.maximum.at(top, tuple(cell.T), z)
    return float(top.mean())


def max_plastic_strain_in_box(lo: Sequence[float], hi: Sequence[float], arrays: Mapping[str, np.ndarray]) -> float:
    """Largest plastic strain of the soil particles inside the box; 0 when there are none."""
    if "plastic_strain" not in arrays:
        return 0.0
    pos = np.asarray(arrays["position"], dtype=float)
    sel = _soil(arrays) & _in_box(pos, lo, hi)
    return float(np.asarray(arrays["plastic_strain"], dtype=float)[sel].max()) if sel.any() else 0.0


def water_depth(point: Sequence[float], arrays: Mapping[str, np.ndarray], dx: float) -> float:
    """Water standing on the ground in the column of `point` (m): water level less soil top, at least 0."""
    p = np.asarray(point, dtype=float)
    lo, hi = p.copy(), p.copy()
    lo[:-1] -= 0.5 * dx
    hi[:-1] += 0.5 * dx
    hi[-1] = np.inf
    ground = soil_level_in_box(lo, hi, arrays, dx)
    return max(water_level(point, arrays, dx) - ground, 0.0)


def water_front_in_box(lo: Sequence[float], hi: Sequence[float], arrays: Mapping[str, np.ndarray]) -> float:
    """Largest x (m) of the active water particles inside the box; the box's low x when there are none."""
    pos = np.asarray(arrays["position"], dtype=float)
    sel = _water(arrays) & _in_box(pos, lo, hi)
    return float(pos[sel, 0].max()) if sel.any() else float(lo[0])


def evaluate(probe, arrays: Mapping[str, np.ndarray], dx: float):
    """Value of one probe (a config `Probe`): a float, or a (dim,) array for velocity."""
    if probe.type == "pressure":
        return pressure_at(probe.point, arrays, dx)
    if probe.type == "water_level":
        return water_level(probe.point, arrays, dx)
    if probe.type == "water_volume":
        return water_volume_in_box(probe.box.min, probe.box.max, arrays)
    if probe.type == "velocity":
        return mean_velocity_in_box(probe.box.min, probe.box.max, arrays)
    if probe.type == "soil_level":
        return soil_level_in_box(probe.box.min, probe.box.max, arrays, dx)
    if probe.type == "plastic_strain":
        return max_plastic_strain_in_box(probe.box.min, probe.box.max, arrays)
    if probe.type == "water_depth":
        return water_depth(probe.point, arrays, dx)
    if probe.type == "water_front":
        return water_front_in_box(probe.box.min, probe.box.max, arrays)
    raise ValueError(f"unknown probe type {probe.type!r}")


class ProbeSet:
    """The probes of a config with their own sampling times (t = 0, then the first step at or after
    each multiple of `every`)."""

    def __init__(self, probes, dim: int, dx: float, default_every: float):
        self.probes = list(probes)
        self.dim = int(dim)
        self.dx = float(dx)
        self.every = [float(p.every or default_every) for p in self.probes]
        self._next = [0.0] * len(self.probes)

    def __len__(self) -> int:
        return len(self.probes)

    def due(self, t: float) -> list[int]:
        """Indices of the probes due at time t."""
        return [k for k, (nxt, ev) in enumerate(zip(self._next, self.every)) if t >= nxt - 1e-9 * ev]

    def sample(self, t: float, arrays: Mapping[str, np.ndarray], which: Sequence[int]) -> dict:
        """Evaluate the probes ``which`` at time t; advances their next sampling time past t."""
        out = {}
        for k in which:
            probe = self.probes[k]
            out[probe.name] = evaluate(probe, arrays, self.dx)
            while self._next[k] <= t + 1e-9 * self.every[k]:
                self._next[k] += self.every[k]
        return out

    def unit(self, k: int) -> str:
        return probe_unit(self.probes[k].type, self.dim)

    def columns(self) -> list[str]:
        """CSV value columns: a probe's name, or <name>_x, <name>_y[, <name>_z] for velocity."""
        cols = []
        for p in self.probes:
            if p.type == "velocity":
                cols += [f"{p.name}_{a}" for a in "xyz"[: self.dim]]
            else:
                cols.append(p.name)
        return cols

    def attrs(self, k: int) -> dict:
        """Description stored on /probes/<name> (type, geometry, interval, unit)."""
        p = self.probes[k]
        a = {"type": p.type, "every": self.every[k], "units": self.unit(k)}
        if p.point is not None:
            a["point"] = [float(v) for v in p.point]
        if p.box is not None:
            a["box_min"] = [float(v) for v in p.box.min]
            a["box_max"] = [float(v) for v in p.box.max]
        return a


class ProbeRecorder:
    """Samples a ProbeSet and records it: rows appended to ``<run>.probes.csv`` as they are taken,
    samples buffered and appended to ``/probes/<name>/time|value`` of the run file by `flush`."""

    def __init__(self, probe_set: ProbeSet, writer, csv_path: str | Path, keep_csv_rows: int | None = None):
        from .io.probe_csv import ProbeCSVWriter

        self.set = probe_set
        self.writer = writer
        self.csv = ProbeCSVWriter(csv_path, probe_set.columns(), keep_rows=keep_csv_rows)
        self._buf: dict[str, tuple[list, list]] = {p.name: ([], []) for p in probe_set.probes}

    def due(self, t: float) -> list[int]:
        return self.set.due(t)

    def record(self, t: float, arrays: Mapping[str, np.ndarray], which: Sequence[int]) -> dict:
        """Sample the probes `which` at t, buffer and write the samples; returns {name: value}."""
        values = self.set.sample(t, arrays, which)
        row = {}
        for name, val in values.items():
            self._buf[name][0].append(t)
            self._buf[name][1].append(val)
            arr = np.atleast_1d(np.asarray(val, dtype=float))
            if arr.size == 1 and np.ndim(val) == 0:
                row[name] = float(arr[0])
            else:
                for a, v in zip("xyz", arr):
                    row[f"{name}_{a}"] = float(v)
        self.csv.append(t, row)
        return values

    def flush(self) -> None:
        for k, probe in enumerate(self.set.probes):
            times, vals = self._buf[probe.name]
            if times:
                self.writer.append_probe(probe.name, times, np.asarray(vals, dtype=float), self.set.unit(k),
                                         attrs=self.set.attrs(k))
                times.clear()
                vals.clear()
        self.csv.flush()

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self.csv.close()
