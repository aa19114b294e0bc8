"""Free-fall case (configs/freefall.yaml): the numbers of docs/freefall.md from run files.

Usage: python tools/freefall_report.py RUN.h5 [RUN.h5 ...]

For each run: eps0 and alpha from the stored config; the time when the lowest water particle
reaches the bottom of the layer (interpolated between frames; the seed reads 0.42 / 0.34 / 0.26 s
for eps0 0.3 / 0.5 / 0.8); the fraction of the water inside the layer at that moment (seed: about
eps0); the water volume drift (sum of m eps / <rho>, docs/output.md) at arrival and at the end;
the bottom pressure against rho_w g times the water depth above the floor; the wall time.
"""

import sys

import numpy as np
import yaml

from taichi_sph.io.hdf5 import RunFile


def analyse(path):
    with RunFile(path) as rf:
        cfg = yaml.safe_load(rf.config_yaml)
        region = cfg["soil"]["regions"][0]
        z_lo, z_hi = region["min"][-1], region["max"][-1]
        water = rf.kind == 0
        times, zmin, frac = rf.times, [], []
        for i in range(rf.n_frames):
            f = rf.frame(i)
            z = f["position"][water & f["active"]][:, -1]
            zmin.append(z.min())
            frac.append(np.mean((z >= z_lo) & (z <= z_hi)))
        zmin, frac = np.array(zmin), np.array(frac)
        k = int(np.argmax(zmin < z_lo)) if np.any(zmin < z_lo) else None
        arrival = frac_at = None
        if k:
            s = (zmin[k - 1] - z_lo) / (zmin[k - 1] - zmin[k])
            arrival = times[k - 1] + s * (times[k] - times[k - 1])
            frac_at = frac[k - 1] + s * (frac[k] - frac[k - 1])
        d = rf.diagnostics()
        vol = d["water_volume"] / d["water_volume"][0] - 1.0
        drift_arrival = float(np.interp(arrival, d["time"], vol)) if arrival else None
        last = rf.frame(-1)
        pos, p = last["position"][water], last["pressure"][water]
        bottom = pos[:, -1] < pos[:, -1].min() + 0.5 * rf.dx
        return {
            "run": str(path), "dx": rf.dx, "eps0": region["eps0"], "alpha": cfg.get("isph", {}).get("alpha", 0.01),
            "arrival_s": arrival, "fraction_in_layer": frac_at, "drift_at_arrival": drift_arrival,
            "drift_end": float(vol[-1]), "end_time": float(times[-1]),
            "bottom_pressure_Pa": float(np.mean(p[bottom])),
            "wall_s": float(np.sum(d["wall_seconds"])) if "wall_seconds" in d else None,
        }


def main(paths):
    print("| dx (m) | eps0 | alpha | arrival (s) | water in layer at arrival | volume drift at arrival | "
          "volume drift at end (t) | wall time (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for path in paths:
        r = analyse(path)
        fmt = lambda v, f: "-" if v is None else format(v, f)
        print(f"| {r['dx']:g} | {r['eps0']:g} | {r['alpha']:g} | {fmt(r['arrival_s'], '.3f')} | "
              f"{fmt(r['fraction_in_layer'], '.3f')} | {fmt(r['drift_at_arrival'], '+.1%')} | "
              f"{r['drift_end']:+.1%} ({r['end_time']:.2f} s) | {fmt(r['wall_s'], '.0f')} |")


if __name__ == "__main__":
    main(sys.argv[1:])
