"""`taichi-sph plot RUN.h5`: PNG plots (matplotlib, no display) of a run's per-step diagnostics
and of its probes over time.

- ``<run>_diagnostics.png``: one panel per diagnostic (dt, kinetic energy, max speed, water volume
  as relative change from the first step, CG iterations and residual, wall time per step, ...);
- ``<run>_probes.png``: one panel per probe (a velocity probe shows each component).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import InputError

#: categorical columns that are not worth a curve
_SKIP = {"time", "dt_limit"}
#: columns drawn on a logarithmic axis
_LOG = {"cg_residual", "ppe_residual"}
#: panels first, in this order
_ORDER = ["dt", "max_speed", "kinetic_energy", "water_volume", "cg_iterations", "cg_residual", "wall_seconds"]


def _figure(n_panels: int):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = 2 if n_panels > 1 else 1
    rows = math.ceil(n_panels / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 2.6 * rows), squeeze=False, sharex=True)
    for ax in axes.ravel()[n_panels:]:
        ax.set_visible(False)
    return plt, fig, axes.ravel()


def plot_diagnostics(run, out: Path) -> Path | None:
    diag = run.diagnostics()
    units = run.diagnostics_units()
    if "time" not in diag or diag["time"].size == 0:
        return None
    t = diag["time"]
    names = [k for k in diag if k not in _SKIP and diag[k].shape == t.shape]
    names.sort(key=lambda k: (_ORDER.index(k) if k in _ORDER else len(_ORDER), k))
    if not names:
        return None
    plt, fig, axes = _figure(len(names))
    for ax, name in zip(axes, names):
        y = diag[name].astype(float)
        label = f"{name} [{units.get(name, '1')}]"
        if name == "water_volume" and y.size and y[0] != 0:
            y = 100.0 * (y / y[0] - 1.0)
            label = "water_volume change [%]"
        ax.plot(t, y, lw=1.0)
        if name in _LOG and np.any(y > 0):
            ax.set_yscale("log")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, alpha=0.3)
    return _finish(plt, fig, axes, f"{run.path.name}: diagnostics per step", out)


def plot_probes(run, out: Path) -> Path | None:
    probes = run.probes()
    if not probes:
        return None
    units = run.probe_units()
    plt, fig, axes = _figure(len(probes))
    for ax, (name, (t, v)) in zip(axes, probes.items()):
        if v.ndim == 2:
            for k in range(v.shape[1]):
                ax.plot(t, v[:, k], marker=".", ms=3, lw=1.0, label="xyz"[k] if k < 3 else str(k))
            ax.legend(fontsize=7)
        else:
            ax.plot(t, v, marker=".", ms=3, lw=1.0)
        ax.set_ylabel(f"{name} [{units.get(name, '1')}]", fontsize=8)
        ax.grid(True, alpha=0.3)
    return _finish(plt, fig, axes, f"{run.path.name}: probes", out)


def _finish(plt, fig, axes, title: str, out: Path) -> Path:
    """Time axes labelled on every panel, the title, and the figure written to `out` and closed."""
    for ax in axes:
        ax.tick_params(labelbottom=True, labelsize=8)
        ax.set_xlabel("time [s]", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def run_command(args) -> int:
    """The `plot` subcommand."""
    import importlib.util

    from .io.hdf5 import RunFile, RunFileError

    if importlib.util.find_spec("matplotlib") is None:
        raise InputError("plot needs the Python package matplotlib: pip install 'taichi-sph[render]'")
    try:
        run = RunFile(args.run_file)
    except RunFileError as exc:
        raise InputError(str(exc)) from None
    with run:
        out_dir = Path(args.out) if args.out else run.path.parent
        if out_dir.exists() and not out_dir.is_dir():
            raise InputError(f"plot --out '{out_dir}': exists and is not a folder")
        diag = run.diagnostics()
        if not run.probes() and ("time" not in diag or diag["time"].size == 0):
            raise InputError(f"{args.run_file}: holds no diagnostics or probes to plot")
        out_dir.mkdir(parents=True, exist_ok=True)
        stem = run.path.stem
        written = [p for p in (plot_diagnostics(run, out_dir / f"{stem}_diagnostics.png"),
                               plot_probes(run, out_dir / f"{stem}_probes.png")) if p is not None]
    for p in written:
        print(f"wrote {p}")
    return 0
