"""`python -m taichi_sph.render [options] SNAPSHOT.npz ...`: draw snapshots taken during a run
(see `during_run`) to PNGs, then delete them. Not meant to be called by hand: use `taichi-sph render`."""

import argparse
import os
import sys
from pathlib import Path

from ..errors import InputError
from .command import CAMERA_CHOICES, WALL_CHOICES, draw_frames, make_plan
from .frames import SnapshotSource


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m taichi_sph.render")
    p.add_argument("snapshots", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument("--field", default="speed")
    p.add_argument("--camera", choices=CAMERA_CHOICES, default="auto")
    p.add_argument("--walls", choices=WALL_CHOICES, default="translucent")
    p.add_argument("--size", default="800x608")
    p.add_argument("--range", dest="clim")
    args = p.parse_args(argv)
    if hasattr(os, "nice"):
        os.nice(10)  # the simulation that started this process keeps its cores
    args.frames, args.slice, args.movie, args.no_png = "all", None, None, False
    paths = [Path(s) for s in args.snapshots]
    src = SnapshotSource(paths)
    try:
        plan = make_plan(src, args, str(paths[0]))
    except InputError as exc:
        print(f"taichi-sph render: {exc}", file=sys.stderr)
        return 2
    draw_frames(src, plan, auto_range_over_frames=False)
    for path in paths:
        path.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
