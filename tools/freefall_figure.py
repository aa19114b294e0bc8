"""Mid-plane pictures of free-fall runs (configs/freefall.yaml) at chosen times, tiled into one
image: one row per run, one column per time, coloured by one field over one range.

Usage: python tools/freefall_figure.py --out docs/img/freefall_seed_times.png \
           --times 0.26,0.34,0.42,0.50,2.50 --field pressure --range 0,2000 RUN.h5 [RUN.h5 ...]

Each picture is drawn by `taichi-sph render` (slice y = half the tank's width, front camera); a
row is labelled with its run's eps0 and alpha. Times are picked as the nearest stored frame.
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, ImageDraw, ImageFont

from taichi_sph.io.hdf5 import RunFile


def frames_at(path, times):
    with RunFile(path) as rf:
        stored = rf.times
        cfg = yaml.safe_load(rf.config_yaml)
        width = cfg["tank"]["size"][1]
    idx = [int(np.argmin(np.abs(stored - t))) for t in times]
    return idx, cfg, width


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--times", required=True, help="comma-separated times (s)")
    ap.add_argument("--field", default="pressure")
    ap.add_argument("--range", dest="clim", required=True, help="lo,hi (the same for every picture)")
    ap.add_argument("--size", default="288x512", help="one picture, WIDTHxHEIGHT")
    args = ap.parse_args(argv)
    times = [float(t) for t in args.times.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, run in enumerate(args.runs):
            idx, cfg, width = frames_at(run, times)
            out = Path(tmp) / f"run{k}"
            cmd = ["taichi-sph", "render", run, "--field", args.field, "--frames", ",".join(map(str, idx)),
                   "--size", args.size, "--slice", f"y={0.5 * width:g}", "--camera", "front",
                   "--range", args.clim, "--out", str(out)]
            subprocess.run(cmd, check=True)
            tiles = [Image.open(out / f"{args.field}_{i:05d}.png").convert("RGB") for i in idx]
            region = cfg["soil"]["regions"][0]
            label = f"eps0 {region['eps0']:g}, alpha {(cfg.get('isph') or {}).get('alpha', 0.01):g}"
            rows.append((label, tiles))
    w, h = rows[0][1][0].size
    pad = 26
    sheet = Image.new("RGB", (w * len(times), (h + pad) * len(rows)), "white")
    draw = ImageDraw.Draw(sheet)
    try:
        font = ImageFont.load_default(size=18)  # Pillow >= 10.1
    except TypeError:
        font = ImageFont.load_default()
    for r, (label, tiles) in enumerate(rows):
        y0 = r * (h + pad)
        draw.text((8, y0 + 3), label, fill="black", font=font)
        for c, tile in enumerate(tiles):
            sheet.paste(tile, (c * w, y0 + pad))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    sheet.quantize(colors=256).save(args.out, optimize=True)  # a palette image: a third of the bytes
    print(args.out)


if __name__ == "__main__":
    sys.exit(main())
