"""Run options: output (frames, pictures), probes, time-step limits, neighbour-list capacity, the
stability guard, checkpoints; and the rules that need dim, the tank or dt (`check_probes`,
`check_images`, `check_times`, run by Config)."""

from __future__ import annotations

from typing import Annotated, Literal, Optional

from pydantic import Field, model_validator

from .base import PosFloat, PosInt, Strict, fail, inside, need_len
from .geometry import Box

#: particle fields a picture made during a run can be coloured by
ImageField = Literal["speed", "pressure", "density", "kind", "porosity", "velocity_x", "velocity_y", "velocity_z"]

#: a name usable as an HDF5 group and a CSV column in numpy and pandas
ProbeName = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", max_length=64)]
#: the geometry each probe type reads
PROBE_GEOMETRY = {"pressure": "point", "water_level": "point", "water_volume": "box", "velocity": "box",
                  "soil_level": "box", "plastic_strain": "box", "water_depth": "point", "water_front": "box"}


class Images(Strict):
    """Pictures while the run goes: at the first frame at or after every `every` seconds the run saves
    that frame's arrays and a separate renderer process draws <run>_images/<field>_<frame>.png (the
    simulation never waits for it and is never affected when rendering fails). Needs the `render` extra."""

    #: simulated seconds between pictures (at least output.every; pictures are made from frames)
    every: PosFloat
    #: particle field that colours the particles: speed, pressure, density, kind, porosity, velocity_x|y|z
    field: ImageField = "speed"
    #: camera preset (auto: front in 2D, iso in 3D)
    camera: Literal["auto", "iso", "front", "top", "side"] = "auto"
    #: wall particles: hidden, translucent or drawn
    walls: Literal["hide", "translucent", "show"] = "translucent"
    #: picture size in pixels [width, height]; rounded up to multiples of 16 so that videos encode cleanly
    size: list[PosInt] = [800, 608]
    #: colour range [lo, hi] in the field's unit; default: automatic for each picture
    range: Optional[list[float]] = None

    @model_validator(mode="after")
    def _size_and_range(self):
        if len(self.size) != 2:
            fail("size", f"needs 2 values [width, height], got {len(self.size)}")
        if max(self.size) > 8192:
            fail("size", f"at most 8192 pixels a side, got {self.size}")
        if self.range is not None and (len(self.range) != 2 or not self.range[1] > self.range[0]):
            fail("range", f"needs [lo, hi] with hi > lo, got {self.range}")
        return self


class Output(Strict):
    #: run file (HDF5); `--out` overrides it
    path: str = "out/run.h5"
    #: simulated seconds between frames
    every: PosFloat = 0.02
    #: HDF5 compression of frame datasets
    compression: Literal["none", "gzip", "lzf"] = "none"
    #: pictures rendered while the run goes (PyVista, in a separate process); none by default
    images: Optional[Images] = None

    @model_validator(mode="after")
    def _images_from_frames(self):
        if self.images is not None and self.images.every < self.every:
            fail("images.every", f"must be at least output.every = {self.every} (pictures are made from frames)")
        return self


class Probe(Strict):
    """A gauge sampled during the run, written to /probes/<name>/time|value of the run file and to
    <run>.probes.csv. See docs/output.md for how each type is computed."""

    #: unique name (letters, digits and '_', not starting with a digit): the HDF5 group and the CSV
    #: column (a velocity probe's columns are <name>_x, <name>_y[, <name>_z])
    name: ProbeName
    #: pressure: SPH (Shepard) pressure of the water at `point` (Pa); water_level: elevation of the
    #: water surface on the vertical line that rises from `point` (m); water_volume: water inside
    #: `box` (m^3, m^2 in 2D); velocity: mean velocity of the water inside `box` (m/s, dim components);
    #: soil_level: mean top of the soil over `box`'s columns (m); plastic_strain: largest plastic strain
    #: of the soil in `box`; water_depth: water standing on the ground at `point`'s column (m);
    #: water_front: the farthest water particle along +x inside `box` (m; a wetting front's foot)
    type: Literal["pressure", "water_level", "water_volume", "velocity", "soil_level", "plastic_strain",
                  "water_depth", "water_front"]
    #: location (m), dim values, inside the tank (types pressure, water_level and water_depth)
    point: Optional[list[float]] = None
    #: region (m), inside the tank (types water_volume, velocity, soil_level, plastic_strain and
    #: water_front)
    box: Optional[Box] = None
    #: simulated seconds between samples (default: output.every); sampled at the first step at or
    #: after each multiple, and at t = 0
    every: Optional[PosFloat] = None

    @model_validator(mode="after")
    def _geometry_of_type(self):
        """A point for the point types, a box for the box types."""
        need = PROBE_GEOMETRY[self.type]
        other = "box" if need == "point" else "point"
        if getattr(self, need) is None:
            fail(need, f"required for a probe of type {self.type}")
        if getattr(self, other) is not None:
            fail(other, f"not used by a probe of type {self.type} (give {need})")
        return self


class TimeStep(Strict):
    """Limits used when dt = auto: dt = min(cfl dx / u_max, viscous dx^2 / nu, force sqrt(dx / |g|)).
    Mode wcsph_biot uses the same three coefficients in its eq 49: dt = min(cfl h / c,
    force sqrt(h / |a|), viscous h^2 / nu) over all particles (h the smoothing length, c the sound speed);
    its one-pass step is stable for cfl below 0.64 (docs/wcsph.md, "One step")."""

    cfl: PosFloat = 0.25
    viscous: PosFloat = 0.125
    force: PosFloat = 0.25
    #: assumed speed (m/s) before the flow starts, e.g. sqrt(2 g H) for a collapse
    initial_speed: Optional[PosFloat] = None
    max: PosFloat = 0.005
    min: PosFloat = 1.0e-7

    @model_validator(mode="after")
    def _ordered(self):
        if self.min > self.max:
            fail("min", "must not exceed timestep.max")
        return self


class Neighbours(Strict):
    #: neighbour-list capacity per particle; default 64 (2D) or 160 (3D). Overflow is an error.
    max: Optional[PosInt] = None


class Guard(Strict):
    """Stability checks made every step (speed, non-finite state) and every `every` steps and frame (the
    rest)."""

    #: stop when any speed exceeds this (m/s); default 20 sqrt(g H_domain)
    max_speed: Optional[PosFloat] = None
    #: particles leaving the domain: remove with a warning and count, or stop the run
    out_of_domain: Literal["remove", "error"] = "remove"
    #: water or air particles inside a wall (past a tank side or into an obstacle by more than dx / 2), found
    #: at the full checks: warn with their count whenever it changes (the run file's attribute
    #: `wall_crossings_max` keeps the most at one check), or stop the run (exit 6, the particles flagged)
    wall_crossing: Literal["warn", "error"] = "warn"
    #: full host-side check (non-finite state, density ratio, wall particles at rest) every this many steps
    #: and at every frame; speed and non-finite reductions are checked every step
    every: PosInt = 10
    #: stop when a water or air particle's density exceeds this multiple of its reference density; default
    #: 1.3 in mode wcsph_biot (Tait pressure ~6 B there) and 3 in mode isph (its number density reaches 1.6
    #: at the floor of a fine dam break that still runs well)
    max_density_ratio: PosFloat | None = None
    #: stop when a soil particle's pore pressure exceeds this in magnitude (Pa; mode wcsph_biot with soil);
    #: default 3 x (g H (rho_w + (1 - n) rho_s) + |u0|): the total vertical stress at the floor of a tank of
    #: height H full of saturated soil, plus the largest initial excess pore pressure u0 (the shipped cases
    #: reach at most 1.8 of that scale: a dry levee's toe as the river is put against it). Where soil raises
    #: the water's sound speed, a pressure wave growing in the pore water changes its density by less than
    #: 1e-3 and its speed stays below 1 m/s: only its pressure shows it (docs/biot.md, "The guard's
    #: pore-pressure bound")
    max_pore_pressure: Optional[PosFloat] = None
    #: stop when a water or air particle's density falls below this multiple of its reference density
    #: (off by default: free-surface particles of mode isph have a low number density)
    min_density_ratio: PosFloat | None = None


class Checkpoint(Strict):
    """Restart points: the full solver state written to <run>.checkpoints/ beside the run file, read by
    `taichi-sph resume RUN.h5`. A run that completes always writes one at its end (so `taichi-sph resume
    RUN.h5 --set end_time=...` extends any finished run), and an interrupted run (Ctrl-C, SIGINT) one
    before it stops."""

    #: simulated seconds between checkpoints; none: only at the end of the run and when it is interrupted
    every: PosFloat | None = None
    #: how many of the newest checkpoints are kept (older ones are deleted)
    keep: PosInt = 2


def check_probes(cfg) -> None:
    """Probe names (and a velocity probe's columns) are unique; geometry has `dim` values and lies in
    the tank; a probe is not sampled more often than dt."""
    seen: dict[str, int] = {}
    for k, probe in enumerate(cfg.probes):
        key = f"probes[{k}]"
        columns = [probe.name]
        if probe.type == "velocity":
            columns += [f"{probe.name}_{a}" for a in "xyz"[: cfg.dim]]
        for col in columns:
            if col in seen:
                fail(f"{key}.name", f"duplicate probe name '{col}' (also probes[{seen[col]}])")
            if col == "time":
                fail(f"{key}.name", "'time' is reserved for the time column")
            seen[col] = k
        if probe.point is not None:
            need_len(probe.point, cfg.dim, f"{key}.point")
            for ax, (v, s) in enumerate(zip(probe.point, cfg.tank.size)):
                if not -1e-12 <= v <= s + 1e-12:
                    fail(f"{key}.point", f"lies outside the tank interior [0, {s}] on axis {ax} "
                         f"(point={probe.point})")
        if probe.box is not None:
            need_len(probe.box.min, cfg.dim, f"{key}.box.min")
            need_len(probe.box.max, cfg.dim, f"{key}.box.max")
            inside(probe.box.min, probe.box.max, cfg.tank.size, f"{key}.box")
        if probe.type in ("soil_level", "plastic_strain") and not (cfg.mode == "wcsph_biot" and cfg.soil_blocks):
            fail(f"{key}.type", f"{probe.type} reads soil particles: it needs mode wcsph_biot with soil_blocks")
        if probe.every is not None and isinstance(cfg.dt, float) and probe.every < cfg.dt:
            fail(f"{key}.every", f"must be at least dt = {cfg.dt}")


def check_images(cfg) -> None:
    """A 2D run is drawn in its plane and has no z velocity."""
    images = cfg.output.images
    if images is None or cfg.dim != 2:
        return
    if images.camera not in ("auto", "front"):
        fail("output.images.camera", f"a 2D run is drawn in its plane: use front or auto, not {images.camera}")
    if images.field == "velocity_z":
        fail("output.images.field", "a 2D run has no velocity_z (its axes are x and y)")


def check_times(cfg) -> None:
    """Frames not more often than a fixed dt; dt below end_time."""
    if isinstance(cfg.dt, float) and cfg.output.every < cfg.dt:
        fail("output.every", f"must be at least dt = {cfg.dt}")
    if isinstance(cfg.dt, float) and cfg.dt >= cfg.end_time:
        fail("dt", f"must be smaller than end_time = {cfg.end_time}")
