"""Driver: config -> scene -> solver -> step loop -> run file. Data flows one way."""

from __future__ import annotations

import gc
import json
import logging
import math
import os
import subprocess
import sys
import time as _time
from pathlib import Path

import numpy as np

from . import __version__
from .config import resolved_yaml
from .contract import DT_CFL, DT_FIXED, DT_FORCE, DT_LIMIT_NAMES, DT_MAX, DT_OUTPUT, DT_VISCOUS
from .errors import InstabilityError
from .guard import StabilityGuard, flag_field
from .scene import build_scene, describe
from .solvers import make_solver

log = logging.getLogger("taichi_sph")

DIAG_COLUMNS = ("time", "dt", "kinetic_energy", "max_speed", "water_volume", "cg_iterations", "cg_residual",
                "wall_seconds", "dt_limit", "free_surface", "collisions", "isolated", "closed_bodies",
                "shift_substeps", "pressure_min", "drag_sum", "drag_max")
#: columns the driver fills itself; the others come from the solver's step() (the ones its
#: `diagnostic_names` lists, contract.Solver)
DRIVER_COLUMNS = ("time", "dt", "wall_seconds", "dt_limit")


def code_version() -> str:
    root = Path(__file__).resolve().parents[1]
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        if rev.returncode == 0 and rev.stdout.strip():
            return f"{__version__}+g{rev.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    return __version__


class TimeStepper:
    """Fixed dt, or dt = min(cfl dx/u, viscous dx^2/nu_E, force sqrt(dx/a_g), max); reports the binding
    limit. u is the largest pore velocity vD / eps (mode isph reports max_speed so); in porous ground of
    smallest porosity eps_min (mode isph) the viscosity is nu_E = nu / eps (eq 9b) and gravity
    accelerates the Darcy velocity at a_g = |g| / eps (eq 19); the drag is implicit and sets no limit."""

    def __init__(self, cfg, g_abs: float):
        self.cfg = cfg
        self.fixed = None if cfg.dt == "auto" else float(cfg.dt)
        self.g_abs = g_abs
        regions = cfg.soil.regions if cfg.mode == "isph" else []
        self.eps_min = min([1.0, *(float(r.eps0) for r in regions)])

    def choose(self, max_speed: float, proposal: tuple[float, int] | None = None) -> tuple[float, int]:
        if proposal is not None:
            return self.cap_proposal(*proposal)
        if self.fixed is not None:
            return self.fixed, DT_FIXED
        ts, dx = self.cfg.timestep, self.cfg.dx
        limits = {DT_MAX: ts.max}
        u = max(max_speed, ts.initial_speed or 0.0)
        if u > 0:
            limits[DT_CFL] = ts.cfl * dx / u
        nu = self.cfg.fluid.viscosity
        if nu > 0:
            limits[DT_VISCOUS] = ts.viscous * dx * dx * self.eps_min / nu
        if self.g_abs > 0:
            limits[DT_FORCE] = ts.force * math.sqrt(dx * self.eps_min / self.g_abs)
        which = min(limits, key=limits.get)
        return max(limits[which], ts.min), which

    def cap_proposal(self, dt: float, limit: int) -> tuple[float, int]:
        """A step the solver proposes (mode wcsph_biot, eq 49), capped by a number given for `dt` or by
        timestep.max."""
        cap, cap_limit = (self.fixed, DT_FIXED) if self.fixed is not None else (self.cfg.timestep.max, DT_MAX)
        return (cap, cap_limit) if dt >= cap else (dt, limit)


class CourantRecord:
    """A run at a fixed dt: its Courant number C = max_speed dt / dx each step (max_speed the largest pore
    velocity in mode isph) against `timestep.cfl`, the bound the adaptive step would hold. Recorded in the
    run file (root attributes `courant_max`, `courant_max_time`, `courant_above_cfl_share`) and, where
    more than 1 % of the steps ran above it, a warning: such a run's results can depend on dt (the
    permeameter at dx 2.5 mm and dt 1 ms, C up to 1.33, drains 3-4 % slower than at 0.5 or 0.25 ms;
    docs/isph.md). The counts go into every checkpoint, so a resumed run reports the whole run."""

    WARN_SHARE = 0.01

    def __init__(self, cfg):
        self.cfl = float(cfg.timestep.cfl)
        self.dt = float(cfg.dt)
        self.steps = 0
        self.above = 0
        self.max = 0.0
        self.max_time = 0.0

    def add(self, t: float, c: float) -> None:
        self.steps += 1
        if c > self.cfl:
            self.above += 1
        if c > self.max:
            self.max, self.max_time = c, t

    def state(self) -> list:
        """The counts so far, for a checkpoint."""
        return [self.steps, self.above, self.max, self.max_time]

    def restore(self, state) -> None:
        """Go on from a checkpoint's counts (`state()`)."""
        steps, above, cmax, cmax_time = state
        self.steps, self.above, self.max, self.max_time = int(steps), int(above), float(cmax), float(cmax_time)

    def report(self, writer, summary: dict) -> None:
        share = self.above / self.steps
        summary.update(courant_max=self.max, courant_above_cfl_share=share)
        writer.set_attrs(courant_max=self.max, courant_max_time=self.max_time, courant_above_cfl_share=share)
        if share > self.WARN_SHARE:
            log.warning("the fixed dt %g s ran above timestep.cfl %g (the adaptive step's bound on max speed "
                        "x dt / dx) in %.1f %% of the steps, at most %.2f (t = %.4g s): results may depend on "
                        "dt; `dt: auto` holds the bound", self.dt, self.cfl, 100 * share, self.max, self.max_time)


class Progress:
    """Progress bar over simulated time with steps/s and ETA (tqdm); quiet when not on a terminal."""

    def __init__(self, end_time: float, enabled: bool | None = None):
        env = os.environ.get("TAICHI_SPH_PROGRESS")
        if enabled is None:
            enabled = env == "1" or (env is None and sys.stderr.isatty())
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=end_time, unit="s", unit_scale=False, dynamic_ncols=True,
                            bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} s [{elapsed}<{remaining}{postfix}]")
        self.t_last = 0.0

    def update(self, t: float, steps_per_s: float, extra: str = ""):
        if self.bar is not None:
            self.bar.update(t - self.t_last)
            self.bar.set_postfix_str(f"{steps_per_s:.1f} steps/s{extra}", refresh=False)
        self.t_last = t

    def close(self):
        if self.bar is not None:
            self.bar.close()


def run(cfg, out_path: str | None = None, arch: str | None = None, progress: bool | None = None,
        resume_from: str | Path | None = None) -> dict:
    """Run a validated config to end_time; returns a summary dict. InstabilityError propagates after the
    run file has been closed with every frame written so far and a last frame of the failing state.
    With `resume_from` (a checkpoint of the run file `out_path`) the run continues from that checkpoint;
    whatever the run file holds past it is cut away. SIGINT (Ctrl-C) stops after the current step and a
    checkpoint; the summary's status is then "interrupted" and KeyboardInterrupt propagates."""
    from . import backend
    from .io.hdf5 import RunWriter

    out_path = out_path or cfg.output.path
    precision = cfg.precision
    if resume_from is not None and precision == "auto":
        precision = _run_file_precision(out_path) or precision  # a resumed run goes on in its own precision
    be = backend.init(arch or cfg.arch, precision, cfg.threads, mode=cfg.mode)
    scene = build_scene(cfg)
    log.info("%s; arch %s, %s", describe(scene), be["arch"], be["precision"])

    t_compile = _time.perf_counter()
    solver = make_solver(cfg, scene)
    stepper = TimeStepper(cfg, solver.g_abs)
    propose = solver.propose_dt if solver.proposes_dt else None  # solvers with their own stability limits

    saved = _resume_state(solver, resume_from) if resume_from is not None else None
    if saved is None:
        writer = RunWriter(out_path, mode=cfg.mode, dim=cfg.dim, dx=cfg.dx, arch=be["arch"],
                           config_yaml=resolved_yaml(cfg), kind=scene.kind, ids=scene.ids, code_version=code_version(),
                           markers=_markers_out(scene),
                           attrs={"precision": be["precision"], "particle_mass": solver.mass, "rho_w": solver.rho_w,
                                  "n_water": solver.n_water, "support_radius": solver.re, "status": "running",
                                  **solver.run_attrs})
    else:
        writer = RunWriter.reopen(out_path, n_frames=saved["n_frames"], n_diagnostics=saved["n_diagnostics"],
                                  probe_samples=saved["probe_samples"])
        writer.set_attrs(config_yaml=resolved_yaml(cfg), status="running", exit_reason="",
                         resumed_from=f"{Path(resume_from).name} (t = {saved['t']:.6g} s)")
    reported = solver.diagnostic_names
    diag = {k: [] for k in DIAG_COLUMNS if k in DRIVER_COLUMNS or k in reported}
    summary = {"out": str(out_path), "arch": be["arch"], "steps": 0, "status": "running"}
    extras = RunExtras(cfg, writer, out_path, scene.kind, solver.mass, solver.rho_w,
                       keep_csv_rows=saved["csv_rows"] if saved is not None else None)
    checkpoints = Checkpoints(cfg, out_path, solver, writer, extras)
    progress_bar = Progress(cfg.end_time, progress)
    wall0 = _time.perf_counter()
    step_wall = 0.0
    volume0 = 0.0
    limit_counts: dict[int, int] = {}  # steps bound by each dt limit (a resumed run: from its start)
    guard = None
    try:
        guard = StabilityGuard(cfg, scene.kind, _reference_density(solver, scene.kind), solver.max_speed_bound(),
                               scene.body, scene.motions, solver.max_pore_pressure_bound())
        every = cfg.output.every
        if saved is None:
            first = solver.initial_diagnostics()
            fields0 = _with_flag(solver.fields_by_id())
            guard.start(fields0)
            extras.after_step(0.0, lambda: fields0)
            _observe(solver, 0.0, extras.readings)
            extras.after_frame(writer.write_frame(0.0, fields0), 0.0, fields0)
            volume0 = first["water_volume"]
            next_out = every
            t = 0.0
            last = first
        else:
            guard.start(_with_flag(solver.fields_by_id()), solver.time)  # walls where their motion put them
            extras.resume(saved)
            volume0, next_out, t, last = saved["volume0"], saved["next_out"], saved["t"], saved["last"]
            checkpoints.next = saved["next_checkpoint"]
            checkpoints.last_step = solver.step_count  # the checkpoint it resumed from
        summary["compile_and_setup_seconds"] = _time.perf_counter() - t_compile
        # the objects made so far (Taichi's kernels and fields, the scene, the config) live as long as the
        # run: kept out of the collector's full passes, which Taichi's launches trigger (~4 % of the main
        # thread's time per step at 20k particles, py-spy)
        gc.freeze()
        n_fixed = None if stepper.fixed is None or propose is not None else int(round(cfg.end_time / stepper.fixed))
        courant = CourantRecord(cfg) if n_fixed is not None else None
        if saved is not None:  # the counts go on from the checkpoint (one written before they were kept: from here)
            limit_counts.update({int(k): v for k, v in saved.get("limit_counts", {}).items()})
            if courant is not None and saved.get("courant"):
                courant.restore(saved["courant"])
            if saved.get("tension"):
                guard.restore_tension(saved["tension"])

        def driver_state() -> dict:
            """What the step loop needs to go on from a checkpoint."""
            return {"t": t, "next_out": next_out, "last": last, "volume0": volume0,
                    "limit_counts": {str(k): v for k, v in limit_counts.items()},
                    "courant": courant.state() if courant is not None else None,
                    "tension": guard.tension_state()}

        checkpoints.catch_sigint()
        while True:
            if n_fixed is not None:
                if solver.step_count >= n_fixed:
                    break
            elif t >= cfg.end_time * (1 - 1e-12):
                break
            dt, limit = stepper.choose(last["max_speed"], propose() if propose is not None else None)
            if n_fixed is None:
                dt, limit = land_on(t, dt, limit, min(next_out, cfg.end_time))
            s0 = _time.perf_counter()
            last = solver.step(dt)
            s1 = _time.perf_counter()
            step_wall += s1 - s0
            t = solver.step_count * stepper.fixed if n_fixed is not None else t + dt
            solver.time = t
            driver = {"time": t, "dt": dt, "wall_seconds": s1 - s0, "dt_limit": limit}
            limit_counts[limit] = limit_counts.get(limit, 0) + 1
            if courant is not None:
                courant.add(t, last["max_speed"] * dt / cfg.dx)
            for key, column in diag.items():
                column.append(driver[key] if key in driver else last[key])
            guard.after_step(solver.step_count, t, last, lambda: _fastest_particle(solver),
                             lambda: solver.fields_by_id()["pressure"])
            fields = extras.after_step(t, lambda: _with_flag(solver.fields_by_id()))
            _observe(solver, t, extras.readings)
            frame_due = t >= next_out - 1e-9 * every
            if frame_due and fields is None:
                fields = _with_flag(solver.fields_by_id())
            if frame_due or guard.due(solver.step_count):
                guard.check_fields(solver.step_count, t, fields if fields is not None else solver.guard_fields())
            if frame_due:
                extras.after_frame(writer.write_frame(t, fields), t, fields)
                _flush_diag(writer, diag)
                while next_out <= t + 1e-9 * every:
                    next_out += every
            if checkpoints.due(t):
                _flush_diag(writer, diag)
                checkpoints.write(t, driver_state())
                if checkpoints.interrupted:
                    raise KeyboardInterrupt
            progress_bar.update(t, solver.step_count / max(step_wall, 1e-9),
                                f", CG {last['cg_iterations']}" if "cg_iterations" in last else f", dt {dt:.3g} s")
        if checkpoints.last_step != solver.step_count:  # every finished run can go on (`taichi-sph resume`)
            _flush_diag(writer, diag)
            checkpoints.write(t, driver_state())
        summary["status"] = "completed"
    except InstabilityError as exc:
        summary["status"] = "unstable"
        summary["error"] = str(exc)
        writer.set_attrs(unstable_quantity=exc.quantity, unstable_family=exc.family, exit_code=exc.exit_code,
                         unstable_step=exc.step, unstable_particles=np.asarray(exc.particles[:1000], dtype=np.int64))
        try:
            writer.write_frame(solver.time, _with_flag(solver.fields_by_id(), exc.particles))
        except Exception:  # noqa: BLE001  (the state may be beyond writing; earlier frames are kept)
            pass
        raise
    except KeyboardInterrupt:
        summary["status"] = "interrupted"
        raise
    finally:
        gc.unfreeze()
        checkpoints.release_sigint()
        progress_bar.close()
        _flush_diag(writer, diag)
        extras.before_close()
        writer.set_attrs(setup_seconds=summary.get("compile_and_setup_seconds"), phase_seconds=dict(solver.timers))
        wall = _time.perf_counter() - wall0
        steps = solver.step_count
        psps = solver.n_fluid * steps / step_wall if step_wall > 0 else 0.0
        summary.update(steps=steps, wall_seconds=wall, step_seconds=step_wall, mipps=psps / 1e6,
                       removed_particles=solver.removed_total, phase_seconds=dict(solver.timers))
        n_limited = sum(limit_counts.values())
        if n_limited:
            share = {DT_LIMIT_NAMES[k]: v / n_limited for k, v in sorted(limit_counts.items())}
            summary["dt_limit_share"] = share
            writer.set_attrs(dt_limit_share=json.dumps(share))
            if stepper.fixed is None:
                log.info("time-step limits that bound: %s",
                         ", ".join(f"{k} {100 * v:.1f} %" for k, v in share.items()))
        if courant is not None and courant.steps:
            courant.report(writer, summary)
        if guard is not None:
            guard.report_tension(writer, summary)
            # most water or air particles inside walls at one check (a resumed run: both parts)
            most = max(guard.crossed_max, int(writer.file.attrs.get("wall_crossings_max", 0)))
            summary["wall_crossings_max"] = most
            writer.set_attrs(wall_crossings_max=most)
            # largest pore-pressure magnitude of a soil particle at one full check (Pa), and the bound (0: none)
            most = max(guard.pore_max, float(writer.file.attrs.get("pore_pressure_max", 0.0)))
            summary["pore_pressure_max"] = most
            writer.set_attrs(pore_pressure_max=most, pore_pressure_bound=guard.pore_bound or 0.0)
        writer.set_attrs(status=summary["status"], exit_reason=summary.get("error", ""), steps=steps,
                         wall_seconds=wall, step_seconds=step_wall, mipps=psps / 1e6,
                         removed_particles=solver.removed_total)
        writer.close()
        extras.after_close(summary["status"])
    if volume0 > 0:
        summary["volume_drift"] = last["water_volume"] / volume0 - 1.0
    return summary


def land_on(t: float, dt: float, limit: int, target: float) -> tuple[float, int]:
    """Shorten an adaptive step so that steps land on `target` without ever becoming tiny: the
    remaining interval r is taken whole when r <= dt and in two halves when dt < r < 2 dt. (A tiny
    step would make the PPE's density term alpha (rho_bar - <rho>) / dt^2 explode.)"""
    r = target - t
    if r <= dt * (1 + 1e-9):
        return r, DT_OUTPUT
    if r < 2 * dt:
        return 0.5 * r, DT_OUTPUT
    return dt, limit


def _markers_out(scene):
    """Soil markers as stored under /markers (SPEC 8: position, porosity = eps0, d50), or None."""
    m = scene.markers
    if not m:
        return None
    return {"position": m["position"], "porosity": m["eps0"], "d50": m["d50"], "volume": m["volume"]}


def _flush_diag(writer, diag):
    if diag["time"]:
        writer.append_diagnostics({k: np.asarray(v) for k, v in diag.items()})
        for v in diag.values():
            v.clear()


def _with_flag(fields: dict, ids=()) -> dict:
    """Frame fields plus `flag` (1 at the particles that stopped the run, see taichi_sph/guard.py)."""
    fields = dict(fields)
    fields["flag"] = flag_field(len(fields["active"]), ids)
    return fields


def _reference_density(solver, kind) -> np.ndarray:
    """Reference density of each particle for the guard's density ratio (air: its own, else water)."""
    from .scene import AIR

    return np.where(np.asarray(kind) == AIR, solver.rho_a if solver.rho_a is not None else solver.rho_w,
                    solver.rho_w)


def _fastest_particle(solver) -> int:
    f = solver.fields_by_id()
    speed = np.linalg.norm(f["velocity"], axis=1)
    return int(np.nanargmax(np.where(np.isfinite(speed), speed, np.inf)))


def _observe(solver, t: float, readings: dict) -> None:
    """Hand the probes' readings at t to a solver that acts on them (a river inflow held at a level)."""
    observe = getattr(solver, "observe_probes", None)
    if readings and observe is not None:
        observe(t, readings)


def probe_arrays(fields: dict, kind: np.ndarray, mass: float, rho_w: float) -> dict:
    """Host arrays for `probes`: frame fields (by id) plus kind and the bulk volume m / (eps rho_w)."""
    arrays = dict(fields, kind=kind)
    volume = np.full(len(kind), mass / rho_w)
    if "porosity" in fields:
        eps = np.asarray(fields["porosity"], dtype=float)
        volume = volume / np.where(eps > 0, eps, 1.0)
    arrays["volume"] = volume
    return arrays


class RunExtras:
    """What a run writes besides frames and diagnostics: probes (sampled when due, to the run file
    and <run>.probes.csv), pictures while it goes (output.images) and, whatever the end, the XDMF
    sidecar of the frames written. None of them can stop the simulation: failures are logged."""

    def __init__(self, cfg, writer, out_path, kind, mass: float, rho_w: float, keep_csv_rows: int | None = None):
        self.readings: dict = {}  # the probes' readings of the last step (after_step)
        from .io.hdf5 import unit_for
        from .io.probe_csv import probe_csv_path

        self.out_path = Path(out_path)
        self.kind = np.asarray(kind)
        self.mass, self.rho_w = float(mass), float(rho_w)
        self.recorder = None
        self.spooler = None
        csv_path = probe_csv_path(self.out_path)
        if cfg.probes:
            from .probes import ProbeRecorder, ProbeSet

            self.recorder = ProbeRecorder(ProbeSet(cfg.probes, cfg.dim, cfg.dx, cfg.output.every), writer, csv_path,
                                          keep_csv_rows=keep_csv_rows)
        elif csv_path.exists():
            csv_path.unlink()  # a stale table of an earlier run with this name
        if cfg.output.images is not None:
            from .render.during_run import ImageSpooler

            f = writer.file
            markers = np.asarray(f["markers/position"][()]) if "markers/position" in f else None
            self.spooler = ImageSpooler(cfg.output.images, self.out_path, dim=cfg.dim, dx=cfg.dx, kind=self.kind,
                                        units={}, markers=markers)
            self._unit_for = lambda name: unit_for(name, cfg.dim)

    def probe_state(self) -> dict:
        """What a checkpoint keeps of the probes: next sampling times and the samples written so far
        (call after `flush`)."""
        if self.recorder is None:
            return {"probe_next": [], "csv_rows": 0, "probe_samples": {}}
        group = self.recorder.writer.file["probes"]
        return {"probe_next": list(self.recorder.set._next), "csv_rows": self.recorder.csv.rows,
                "probe_samples": {name: int(group[name]["time"].shape[0]) for name in group}}

    def resume(self, saved: dict) -> None:
        """Continue sampling where a checkpoint left off."""
        if self.recorder is not None and saved["probe_next"]:
            self.recorder.set._next = [float(v) for v in saved["probe_next"]]

    def after_step(self, t: float, fetch):
        """Sample the probes due at t; returns the fetched fields (None when nothing was due). The
        readings taken are left in `readings` ({probe name: value}, empty when none was due)."""
        self.readings = {}
        if self.recorder is None:
            return None
        due = self.recorder.due(t)
        if not due:
            return None
        fields = fetch()
        self.readings = self.recorder.record(t, probe_arrays(fields, self.kind, self.mass, self.rho_w), due)
        return fields

    def after_frame(self, index: int, t: float, fields: dict) -> None:
        if self.recorder is not None:
            self.recorder.flush()
        if self.spooler is not None and self.spooler.due(t):
            try:
                self.spooler.units = {k: self._unit_for(k) for k in fields}
                self.spooler.add(index, t, fields)
            except Exception as exc:  # noqa: BLE001  (pictures never stop a run)
                self.spooler.failed = True
                log.warning("output.images: no more pictures (%s)", exc)

    def before_close(self) -> None:
        if self.recorder is not None:
            try:
                self.recorder.close()
            except Exception as exc:  # noqa: BLE001
                log.warning("probes: last samples not written (%s)", exc)

    def after_close(self, status: str) -> None:
        from .io.xdmf import write_xdmf

        try:
            write_xdmf(self.out_path, markers=True)
        except Exception as exc:  # noqa: BLE001  (the run file itself is complete)
            log.warning("XDMF sidecar not written: %s", exc)
        if self.spooler is not None:
            try:
                self.spooler.finish(wait=status != "interrupted")
                if self.spooler.count and not self.spooler.failed:
                    log.info("%d picture(s) in %s", self.spooler.count, self.spooler.out_dir)
            except Exception as exc:  # noqa: BLE001
                log.warning("output.images: %s", exc)


class Checkpoints:
    """Checkpoints of a run (config section `checkpoint`, io/checkpoint.py): due every `every` simulated
    seconds and whenever SIGINT has asked the run to stop; the driver writes one more at the end of a
    completed run (unless one was just written there), so any finished run can be resumed with a later
    end_time. Each holds the solver's `state()` and the step loop's own state, after the run file has
    been flushed up to that moment. `last_step` is the solver step of the newest one this process wrote
    (None before the first)."""

    def __init__(self, cfg, out_path, solver, writer, extras):
        self.every = cfg.checkpoint.every
        self.keep = cfg.checkpoint.keep
        self.next = self.every
        self.out_path = out_path
        self.solver, self.writer, self.extras = solver, writer, extras
        self.interrupted = False
        self.last_step = None
        self._previous_handler = None

    def catch_sigint(self) -> None:
        """The first SIGINT asks for a stop after the current step (with a checkpoint); a second one
        interrupts at once. Only in the main thread (elsewhere signals cannot be caught)."""
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return

        def ask_stop(signum, frame):
            self.interrupted = True
            log.warning("interrupt: stopping after this step with a checkpoint (interrupt again to stop at once)")
            signal.signal(signal.SIGINT, signal.default_int_handler)

        self._previous_handler = signal.signal(signal.SIGINT, ask_stop)

    def release_sigint(self) -> None:
        import signal

        if self._previous_handler is not None:
            signal.signal(signal.SIGINT, self._previous_handler)
            self._previous_handler = None

    def due(self, t: float) -> bool:
        return self.interrupted or (self.every is not None and t >= self.next - 1e-9 * self.every)

    def write(self, t: float, loop_state: dict) -> Path:
        from .io.checkpoint import write_checkpoint

        if self.extras.recorder is not None:
            self.extras.recorder.flush()
        if self.every is not None:
            while self.next <= t + 1e-9 * self.every:
                self.next += self.every
        diag = self.writer.file["diagnostics"]
        driver = dict(loop_state, next_checkpoint=self.next, n_frames=self.writer.n_frames,
                      n_diagnostics=int(diag["time"].shape[0]) if "time" in diag else 0,
                      **self.extras.probe_state())
        path = write_checkpoint(self.out_path, self.solver.step_count, t, self.solver.state(), driver, self.keep)
        self.last_step = self.solver.step_count
        log.info("checkpoint at t = %.6g s (step %d): %s", t, self.solver.step_count, path)
        return path


def _run_file_precision(path) -> str | None:
    """The precision a run file was written in (its root attribute), or None if it has none."""
    from .io.hdf5 import RunFile

    with RunFile(path) as rf:
        value = rf.attrs.get("precision")
    return None if value is None else str(value)


def _resume_state(solver, checkpoint) -> dict:
    """Load a checkpoint into the solver; returns the step loop's saved state."""
    from .errors import InputError
    from .io.checkpoint import read_checkpoint
    from .sph.state import StateMismatchError

    state, driver, _ = read_checkpoint(checkpoint)
    try:
        solver.load_state(state)
    except StateMismatchError as exc:
        raise InputError(f"checkpoint '{checkpoint}' does not fit the config: {exc}") from None
    return driver
