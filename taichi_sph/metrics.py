"""Metrics: numbers computed from a finished run file, as the config's `metrics` section defines them
(schema.Metric). Each reads one time series, a probe (/probes/<name>) or a per-step diagnostic
(/diagnostics/<name> against /diagnostics/time), and reduces it:

- final, max, min: the last, largest, smallest sample;
- mean: time average by the trapezoid rule over the sampled interval;
- at: the value at a time (a number, or an earlier metric's value such as an arrival time), linearly
  interpolated between samples; NaN outside the sampled interval;
- first_above / first_below: the first time the series reaches the level from below / above,
  linearly interpolated between the two samples around the crossing; NaN if it never does (a series
  that starts beyond the level crosses at its first sample).

A vector probe (velocity) reads its `component`, or its magnitude. This module imports numpy and the
run-file reader only.
"""

from __future__ import annotations

import math

import numpy as np

from .io.hdf5 import RunFile


def series(rf: RunFile, metric) -> tuple[np.ndarray, np.ndarray]:
    """(times, values) the metric reads from an open run file; KeyError naming what is missing."""
    if metric.probe is not None:
        probes = rf.probes()
        if metric.probe not in probes:
            raise KeyError(f"run file has no probe '{metric.probe}'")
        t, v = probes[metric.probe]
        v = np.asarray(v, dtype=float)
        if v.ndim == 2:
            v = v[:, metric.component] if metric.component is not None else np.linalg.norm(v, axis=1)
        return np.asarray(t, dtype=float), v
    diag = rf.diagnostics()
    if metric.diagnostic not in diag:
        raise KeyError(f"run file has no diagnostic '{metric.diagnostic}'")
    return np.asarray(diag["time"], dtype=float), np.asarray(diag[metric.diagnostic], dtype=float)


def reduce(t: np.ndarray, v: np.ndarray, stat: str, time: float | None = None, level: float | None = None) -> float:
    """One number from a time series (see the module docstring)."""
    if t.size == 0:
        return math.nan
    if stat == "final":
        return float(v[-1])
    if stat == "max":
        return float(np.max(v))
    if stat == "min":
        return float(np.min(v))
    if stat == "mean":
        if t.size == 1 or t[-1] == t[0]:
            return float(v[0])
        trapezoid = getattr(np, "trapezoid", None) or np.trapz  # numpy < 2 names it trapz
        return float(trapezoid(v, t) / (t[-1] - t[0]))
    if stat == "at":
        if time is None or not math.isfinite(time) or time < t[0] - 1e-12 or time > t[-1] + 1e-12:
            return math.nan
        return float(np.interp(time, t, v))
    if stat in ("first_above", "first_below"):
        beyond = v >= level if stat == "first_above" else v <= level
        hit = np.flatnonzero(beyond)
        if hit.size == 0:
            return math.nan
        k = int(hit[0])
        if k == 0:
            return float(t[0])
        v0, v1 = v[k - 1], v[k]
        f = (level - v0) / (v1 - v0) if v1 != v0 else 1.0
        return float(t[k - 1] + f * (t[k] - t[k - 1]))
    raise ValueError(f"unknown stat {stat!r}")


def compute(metrics, run_path) -> dict[str, float]:
    """{metric name: value} for a run file; a metric whose series is missing is NaN."""
    out: dict[str, float] = {}
    with RunFile(run_path) as rf:
        for m in metrics:
            try:
                t, v = series(rf, m)
            except KeyError:
                out[m.name] = math.nan
                continue
            time = out.get(m.time, math.nan) if isinstance(m.time, str) else m.time
            out[m.name] = reduce(t, v, m.stat, time, m.level)
    return out
