"""Sweeps: the metrics a config defines (one column each of the table `taichi-sph sweep` gathers,
docs/sweep.md) with the rules that tie them to the probes (`check_metrics`, run by Config), and the
sweep file (`SweepFile`, read by `load_sweep_file`)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..errors import InputError
from .base import NonNegFloat, PosInt, Strict, fail
from .run_options import ProbeName

#: per-step diagnostics a metric can read (run file /diagnostics/<name>)
MetricDiagnostic = Literal["kinetic_energy", "max_speed", "water_volume", "cg_iterations", "cg_residual", "dt",
                           "wall_seconds", "free_surface", "collisions", "isolated", "pressure_min"]


class Metric(Strict):
    """A number computed from a finished run (a probe or a diagnostic reduced over time), one column of
    the table `taichi-sph sweep` gathers. See docs/sweep.md."""

    #: column name in the sweep table (letters, digits and '_')
    name: ProbeName
    #: the time series it reads: a probe's name (probes[k].name) ...
    probe: str | None = None
    #: ... or a per-step diagnostic
    diagnostic: MetricDiagnostic | None = None
    #: for a velocity probe: component index (0 = x); default the speed (magnitude)
    component: Annotated[int, Field(ge=0, le=2)] | None = None
    #: final: last value; max, min; mean: time average (trapezoid); at: value at `time` (linear
    #: interpolation); first_above / first_below: first time (s) the series crosses `level` (interpolated)
    stat: Literal["final", "max", "min", "mean", "at", "first_above", "first_below"] = "final"
    #: for stat at: a time (s) or the name of an earlier metric whose value is a time
    time: NonNegFloat | str | None = None
    #: for stat first_above / first_below: the level, in the series' unit
    level: float | None = None

    @model_validator(mode="after")
    def _keys_of_stat(self):
        """One series; `time` with stat at only, `level` with the first_* stats only."""
        if (self.probe is None) == (self.diagnostic is None):
            fail("", "give exactly one of `probe` and `diagnostic`")
        if self.stat == "at":
            if self.time is None:
                fail("time", "required for stat at")
        elif self.time is not None:
            fail("time", f"applies to stat at only (stat is {self.stat})")
        if self.stat in ("first_above", "first_below"):
            if self.level is None:
                fail("level", f"required for stat {self.stat}")
        elif self.level is not None:
            fail("level", f"applies to stats first_above and first_below only (stat is {self.stat})")
        return self


def check_metrics(cfg) -> None:
    """Metric names are unique; a probe a metric reads exists (a velocity probe for `component`, below
    dim); a time given by name is an earlier metric's."""
    probes = {p.name: p for p in cfg.probes}
    seen: list[str] = []
    for k, m in enumerate(cfg.metrics):
        key = f"metrics[{k}]"
        if m.name in seen:
            fail(f"{key}.name", f"duplicate metric name '{m.name}'")
        if m.probe is not None and m.probe not in probes:
            fail(f"{key}.probe", f"no probe named '{m.probe}' (probes: {', '.join(probes) or 'none'})")
        if m.component is not None and (m.probe is None or probes[m.probe].type != "velocity"):
            fail(f"{key}.component", "applies to a velocity probe only")
        if m.component is not None and m.component >= cfg.dim:
            fail(f"{key}.component", f"must be below dim = {cfg.dim}")
        if m.stat == "at" and isinstance(m.time, str) and m.time not in seen:
            fail(f"{key}.time", f"'{m.time}' is neither a number nor the name of an earlier metric")
        seen.append(m.name)


class SweepFile(BaseModel):
    """A sweep file (YAML; taichi_sph/sweep.py, docs/sweep.md)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    #: the case file, relative to the sweep file
    config: str
    #: a variant of the case file (its `variants` section) applied before `set` and the swept entries
    variant: str | None = None
    #: output folder (relative to the working directory); default out/sweep_<config name>
    out: str | None = None
    #: overrides for every case (dotted keys; values may be lists or maps)
    set: dict[str, Any] | None = None
    #: dotted key -> list of values (a single value is a list of one); the cases are every combination
    grid: dict[str, Any] | None = None
    #: a list of cases (dotted keys -> values, `name` to name one), each crossed with the grid
    cases: list[dict[str, Any]] | None = None
    #: cases run at once on this machine (default 1; --workers overrides it)
    workers: PosInt | None = None


#: the one-line message of a bad key of a sweep file, in the order they are reported
SWEEP_KEY_ERRORS = {
    "config": "key 'config' (the case file) is required",
    "variant": "key 'variant' must be the name of one of the case file's variants",
    "out": "key 'out' must be a folder name",
    "workers": "key 'workers' must be a positive integer",
    "set": "key 'set' must be a mapping of dotted keys",
    "grid": "key 'grid' must be a mapping of dotted keys",
    "cases": "key 'cases' must be a list of mappings",
}


def load_sweep_file(path) -> SweepFile:
    """The validated sweep file (InputError, one line naming the file and the key)."""
    from .load import read_yaml

    data = read_yaml(path)
    try:
        return SweepFile.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        unknown = sorted(str(e["loc"][0]) for e in errors if e["type"] == "extra_forbidden")
        if unknown:
            keys = ", ".join(sorted(SweepFile.model_fields))
            raise InputError(f"sweep file '{path}': unknown key '{unknown[0]}' (keys: {keys})") from None
        bad = {str(e["loc"][0]) for e in errors}
        first = next(key for key in SWEEP_KEY_ERRORS if key in bad)
        raise InputError(f"sweep file '{path}': {SWEEP_KEY_ERRORS[first]}") from None
