"""`taichi-sph render RUN.h5`: PNG pictures of chosen frames and MP4/GIF movies.

Every option is checked before anything is drawn or written; a bad option, file, field, frame
number or slice is an InputError (one line, exit code 2), and so is a machine that cannot render
offscreen (checked in a subprocess first).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from . import frames as fr

CAMERA_CHOICES = ("auto", "iso", "front", "top", "side")
WALL_CHOICES = ("translucent", "hide", "show")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_file", help="run file (HDF5)")
    p.add_argument("--field", "-f", default="pressure",
                   help="colour field: pressure, speed, density, porosity, kind, velocity_x, ... (default pressure)")
    p.add_argument("--frames", default="all",
                   help="frame numbers, e.g. 0,5,-1 (negative from the end), a range 0:20:2, or all (default)")
    p.add_argument("--out", help="folder for the PNGs (default: <run>_images beside the run file)")
    p.add_argument("--movie", help="also write a movie of the chosen frames: out.mp4 or out.gif")
    p.add_argument("--fps", type=float, default=10.0, help="movie frames per second (default 10)")
    p.add_argument("--no-png", action="store_true", help="write the movie only")
    p.add_argument("--size", default="1024x768", help="picture size WIDTHxHEIGHT in pixels, rounded up to "
                   "multiples of 16 (default 1024x768)")
    p.add_argument("--range", dest="clim", help="colour range lo,hi in the field's unit (default: automatic, "
                   "the same for all chosen frames)")
    p.add_argument("--slice", help="cross-section of a 3D run: AXIS=VALUE, e.g. y=0.1 (particles within one dx "
                   "of the plane)")
    p.add_argument("--camera", choices=CAMERA_CHOICES, default="auto",
                   help="view: iso, front (along y), top, side (along x); auto: front in 2D or across a slice, "
                   "else iso")
    p.add_argument("--walls", choices=WALL_CHOICES, default="translucent", help="wall particles (default translucent)")


@dataclass
class Plan:
    field: str
    unit: str
    categorical: bool
    indices: list[int]
    out_dir: Path | None
    movie: Path | None
    fps: float
    size: tuple[int, int]
    clim: tuple[float, float] | None
    slice_axis: int | None
    slice_value: float
    camera: str
    walls: str


def parse_frames(text: str, n: int, where: str) -> list[int]:
    """'all', '0,5,-1', '0:20:2' (and mixtures) -> frame indices in [0, n)."""
    text = text.strip()
    if text == "all":
        return list(range(n))
    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            if ":" in part:
                bits = [int(b) if b.strip() else None for b in part.split(":")]
                if len(bits) > 3:
                    raise ValueError
                out += list(range(n))[slice(*bits)]
                continue
            i = int(part)
        except ValueError:
            raise InputError(f"render --frames '{text}': expected frame numbers like 0,5,-1, a range 0:20:2, "
                             "or all") from None
        if not -n <= i < n:
            raise InputError(f"render --frames: frame {i} out of range ({n} frames in {where})")
        out.append(i % n)
    if not out:
        raise InputError(f"render --frames '{text}': selects no frame ({n} frames in {where})")
    return out


def parse_pair(text: str, sep: str, cast, option: str, example: str):
    parts = text.lower().split(sep)
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = cast(parts[0]), cast(parts[1])
    except ValueError:
        raise InputError(f"render {option} '{text}': expected {example}") from None
    return a, b


def domain_bounds(src: fr.FrameSource) -> tuple[np.ndarray, np.ndarray]:
    """Extent of the particle centres of frame 0 (and of the soil markers)."""
    pos = np.asarray(src.read("position", 0), dtype=float)
    if src.markers is not None and len(src.markers):
        pos = np.concatenate([pos, np.asarray(src.markers, dtype=float)])
    return pos.min(axis=0), pos.max(axis=0)


def make_plan(src: fr.FrameSource, args, where: str) -> Plan:
    """Check every option against the run; raises InputError naming the option."""
    n = src.n_frames
    if n == 0:
        raise InputError(f"{where}: holds no frames to render")
    if "position" not in src.field_names:
        raise InputError(f"{where}: frames have no 'position' field")
    try:
        _, unit, categorical = fr.resolve_field(src, args.field)
    except KeyError:
        have = ", ".join(fr.colour_fields(src))
        raise InputError(f"render --field '{args.field}': no such field in {where} (have: {have})") from None
    indices = parse_frames(args.frames, n, where)

    w, h = parse_pair(args.size, "x", int, "--size", "WIDTHxHEIGHT such as 1024x768")
    if not (0 < w <= 8192 and 0 < h <= 8192):
        raise InputError(f"render --size '{args.size}': width and height must be 1 to 8192 pixels")
    clim = None
    if args.clim:
        clim = parse_pair(args.clim, ",", float, "--range", "lo,hi such as 0,3000")
        if not (np.isfinite(clim).all() and clim[1] > clim[0]):
            raise InputError(f"render --range '{args.clim}': needs finite lo < hi")

    axis, value = None, 0.0
    if args.slice:
        if src.dim == 2:
            raise InputError("render --slice: a 2D run is drawn whole in its plane; leave --slice out")
        name, value = parse_pair(args.slice, "=", str, "--slice", "AXIS=VALUE such as y=0.1")
        name = name.strip()
        if name not in fr.AXES[: src.dim]:
            raise InputError(f"render --slice '{args.slice}': axis must be x, y or z")
        try:
            value = float(value)
        except ValueError:
            raise InputError(f"render --slice '{args.slice}': expected AXIS=VALUE such as y=0.1") from None
        axis = fr.AXES.index(name)
        lo, hi = domain_bounds(src)
        if not (lo[axis] - src.dx <= value <= hi[axis] + src.dx) or not np.isfinite(value):
            raise InputError(f"render --slice {args.slice}: outside the domain ({name} from {lo[axis]:.4g} to "
                             f"{hi[axis]:.4g} m)")

    camera = args.camera
    if src.dim == 2 and camera not in ("auto", "front"):
        raise InputError(f"render --camera {camera}: a 2D run is drawn in its plane; use front or auto")
    if camera == "auto":
        camera = "front" if src.dim == 2 else {None: "iso", 0: "side", 1: "front", 2: "top"}[axis]

    movie = None
    if getattr(args, "movie", None):
        movie = Path(args.movie)
        if movie.suffix.lower() not in (".mp4", ".gif"):
            raise InputError(f"render --movie '{args.movie}': must end in .mp4 or .gif")
        if movie.is_dir():
            raise InputError(f"render --movie '{args.movie}' is a directory")
        if not args.fps > 0:
            raise InputError(f"render --fps {args.fps}: must be positive")
    out_dir = None
    if not getattr(args, "no_png", False):
        out_dir = Path(args.out) if args.out else default_out_dir(Path(where))
        if out_dir.exists() and not out_dir.is_dir():
            raise InputError(f"render --out '{out_dir}': exists and is not a folder")
    elif movie is None:
        raise InputError("render --no-png: nothing to write without --movie")
    return Plan(field=args.field, unit=unit, categorical=categorical, indices=indices, out_dir=out_dir, movie=movie,
                fps=float(getattr(args, "fps", 10.0)), size=(w, h), clim=clim, slice_axis=axis, slice_value=value,
                camera=camera, walls=args.walls)


def default_out_dir(run_path: Path) -> Path:
    return run_path.with_name(run_path.stem + "_images")


def png_name(field: str, label: int) -> str:
    return f"{field}_{label:05d}.png"


def draw_frames(src: fr.FrameSource, plan: Plan, auto_range_over_frames: bool = True) -> tuple[list[Path], Path | None]:
    """Draw the plan's frames; returns the PNG paths and the movie path (None when not asked)."""
    from .draw import Drawing, auto_range, write_movie

    def keep_mask(i):
        pos = np.asarray(src.read("position", i), dtype=float)
        keep = np.asarray(src.read("active", i), dtype=bool) if "active" in src.field_names else np.ones(len(pos), bool)
        if plan.slice_axis is not None:
            keep &= np.abs(pos[:, plan.slice_axis] - plan.slice_value) <= src.dx
        return pos, keep

    clim = plan.clim
    if clim is None and not plan.categorical and auto_range_over_frames:
        vals = []
        for i in plan.indices:
            _, keep = keep_mask(i)
            keep &= src.kind != 1
            vals.append(fr.scalar_field(src, plan.field, i)[keep])
        clim = auto_range(np.concatenate(vals) if vals else np.zeros(0))
    title = f"{plan.field} [{plan.unit}]" if not plan.categorical else "kind"
    lo, hi = domain_bounds(src)
    half = 0.5 * src.dx  # particles are drawn as spheres of diameter dx around their centres
    drawing = Drawing(dim=src.dim, dx=src.dx, size=plan.size, camera=plan.camera, walls=plan.walls, title=title,
                      clim=clim, categorical=plan.categorical, bounds=(lo - half, hi + half), markers=src.markers)
    pngs, images = [], []
    try:
        if plan.out_dir is not None:
            plan.out_dir.mkdir(parents=True, exist_ok=True)
        for i in plan.indices:
            pos, keep = keep_mask(i)
            img = drawing.draw(pos, src.kind, fr.scalar_field(src, plan.field, i), float(src.times[i]), keep)
            if plan.out_dir is not None:
                path = plan.out_dir / png_name(plan.field, src.label(i))
                _save_png(path, img)
                pngs.append(path)
            if plan.movie is not None:
                images.append(img)
    finally:
        drawing.close()
    if plan.movie is not None:
        plan.movie.parent.mkdir(parents=True, exist_ok=True)
        write_movie(plan.movie, images, plan.fps)
    return pngs, plan.movie


def _save_png(path: Path, img: np.ndarray) -> None:
    from PIL import Image

    tmp = path.with_name(path.name + ".part")
    Image.fromarray(img).save(tmp, format="PNG", optimize=True)
    tmp.replace(path)


def run_command(args) -> int:
    """The `render` subcommand: checks every option here, then draws in a child process, so that a
    machine without offscreen OpenGL (VTK crashes there) gets one line and exit code 2."""
    import json
    import os
    import subprocess
    import sys

    from ..io.hdf5 import RunFile, RunFileError
    from .offscreen import configure_env, crash_message, missing_modules

    try:
        run = RunFile(args.run_file)
    except RunFileError as exc:
        raise InputError(str(exc)) from None
    src = fr.RunSource(run)
    try:
        plan = make_plan(src, args, str(args.run_file))
    finally:
        src.close()
    missing = missing_modules(str(plan.movie) if plan.movie else None)
    if missing:
        raise InputError(f"render needs the Python package(s) {', '.join(m.replace('_', '-') for m in missing)}: "
                         "pip install 'taichi-sph[render]'")
    options = {k: v for k, v in vars(args).items() if k != "command"}
    res = subprocess.run([sys.executable, "-m", "taichi_sph.render.command", json.dumps(options)], check=False,
                         stderr=subprocess.PIPE, text=True, env=configure_env(dict(os.environ)))
    if res.returncode < 0:
        raise InputError(f"render: {crash_message(res.returncode)}")
    if res.returncode != 0:
        lines = [ln.strip() for ln in res.stderr.splitlines() if ln.strip()]
        last = lines[-1] if lines else f"exit code {res.returncode}"
        if res.returncode == 2:
            raise InputError(last.removeprefix("taichi-sph: error: "))
        print(f"taichi-sph: error: render failed: {last}", file=sys.stderr)
        return 1
    return 0


def _child(options_json: str) -> int:
    """Drawing process: a tiny test picture first (nothing is written if it fails), then the frames."""
    import argparse
    import json
    import sys

    from ..io.hdf5 import RunFile
    from .offscreen import PACKAGES_HINT, probe_render

    args = argparse.Namespace(**json.loads(options_json))
    try:
        probe_render()
    except Exception as exc:  # noqa: BLE001  (any failure to draw means: not available here)
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"taichi-sph: error: render: offscreen rendering is not available on this machine: {msg} "
              f"({PACKAGES_HINT})", file=sys.stderr)
        return 2
    src = fr.RunSource(RunFile(args.run_file))
    try:
        plan = make_plan(src, args, str(args.run_file))
        pngs, movie = draw_frames(src, plan)
    finally:
        src.close()
    if pngs:
        print(f"wrote {len(pngs)} picture(s) to {plan.out_dir}")
    if movie:
        print(f"wrote {movie} ({len(plan.indices)} frames at {plan.fps:g} fps)")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(_child(sys.argv[1]))
