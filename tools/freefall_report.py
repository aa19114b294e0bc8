"""Free-fall case (configs/freefall.yaml): the numbers of docs/freefall.md from run files.

Usage: python tools/freefall_report.py RUN.h5 [RUN.h5 ...]

For each run: dx, dt, eps0 and alpha from the stored config; the time when the lowest water
particle reaches the bottom of the layer (interpolated between frames; the seed reads 0.42 / 0.34 /
0.26 s for eps0 0.3 / 0.5 / 0.8); the water body's arrival, when the share of the water below the
layer's top first reaches eps0 times the layer's depth over the block's height
(porosity.bulk_front_arrival: the 1D front's arrival, where the seed reads about eps0 of the water in
the layer); the fraction of the water inside the layer when the lowest particle arrives (seed: about
eps0); the water in the layer's core (farther than r_e = 2.4 dx from its top and bottom) per pore
volume over 0.6-1.2 s, while the water passes it, counted without a kernel: the particles' centres,
and each particle as a slab of the pore lattice's row spacing dx / eps0^(1/dim) (porosity.slab_count:
at dx 2 cm the core holds about 3.5 rows and a count of centres moves by a row as rows cross its
faces); the water volume measure (sum of m eps / <rho>, docs/output.md) against t = 0 at
arrival, its lowest and highest value over the run and its mean over the last 0.25 s (the last
sample alone scatters with the sloshing pool); the water still inside the layer at the end; the
bottom pressure at the end against hydrostatic, and the pool's vertical pressure gradient against
rho_w g; the largest particle speed over the run (|vD| of /diagnostics/max_speed) and the time it
occurred; whether the run reached its end time (a run the guard stopped keeps its frames: the time it
stopped); the particle shifting and near-contact collision options (isph.shifting,
isph.collision_distance; "off" when 0) and the advection (isph.advection); the wall time of the run.

Bottom pressure: the mean pressure of the bottom row of water particles (centres within half a
spacing of the lowest) against the mean of rho_w g (s - z), with the pool's surface s taken as the
99th percentile of the heights of the water below the layer plus half a spacing (the Dirichlet
value of a free-surface particle, rho_w g dx / 2, puts the surface there). The water is still
draining and sloshing at 2.5 s, so this estimates the settled state; it is not a hydrostatic test.
"""

import sys

import numpy as np
import yaml

from taichi_sph.io.hdf5 import RunFile
from taichi_sph.isph.porosity import bulk_front_arrival, slab_count
from taichi_sph.sph.kernels import SUPPORT_FACTOR
from validate import FREEFALL_ARRIVAL  # the seed's arrival times (tools/ is this script's folder)


def analyse(path):
    with RunFile(path) as rf:
        cfg = yaml.safe_load(rf.config_yaml)
        region = cfg["soil"]["regions"][0]
        z_lo, z_hi = region["min"][-1], region["max"][-1]
        water = rf.kind == 0
        eps0 = float(region["eps0"])
        # the layer's core and the particles its pores hold (each particle's water volume dx^dim)
        core_lo, core_hi = z_lo + SUPPORT_FACTOR * rf.dx, z_hi - SUPPORT_FACTOR * rf.dx
        plan = float(np.prod([b - a for a, b in zip(region["min"][:-1], region["max"][:-1])]))
        pores = eps0 * plan * (core_hi - core_lo) / rf.dx**rf.dim
        row = rf.dx / eps0 ** (1.0 / rf.dim)
        times, zmin, frac, entered, centres, slabs = rf.times, [], [], [], [], []
        for i in range(rf.n_frames):
            f = rf.frame(i)
            z = f["position"][water & f["active"]][:, -1]
            zmin.append(z.min())
            frac.append(np.mean((z >= z_lo) & (z <= z_hi)))
            entered.append(np.mean(z < z_hi))
            centres.append(np.sum((z > core_lo) & (z < core_hi)) / pores)
            slabs.append(slab_count(z, core_lo, core_hi, row) / pores)
        zmin, frac = np.array(zmin), np.array(frac)
        passing = (times >= 0.6 - 1e-9) & (times <= 1.2 + 1e-9)
        core = None
        if passing.sum() > 1:
            c, sl = np.array(centres)[passing], np.array(slabs)[passing]
            core = (float(c.mean()), float(c.min()), float(c.max()), float(sl.mean()), float(sl.min()),
                    float(sl.max()))
        block = cfg["water"][0]
        body = bulk_front_arrival(times, entered, eps0, z_hi - z_lo,
                                  float(block["max"][-1]) - float(block["min"][-1]))
        k = int(np.argmax(zmin < z_lo)) if np.any(zmin < z_lo) else None
        arrival = frac_at = None
        if k:
            s = (zmin[k - 1] - z_lo) / (zmin[k - 1] - zmin[k])
            arrival = times[k - 1] + s * (times[k] - times[k - 1])
            frac_at = frac[k - 1] + s * (frac[k] - frac[k - 1])
        d = rf.diagnostics()
        t = d["time"]
        vol = d["water_volume"] / d["water_volume"][0] - 1.0
        drift_arrival = float(np.interp(arrival, t, vol)) if arrival else None
        settled = t >= t[-1] - 0.25
        last = rf.frame(-1)
        sel = water & last["active"]
        pos, p = last["position"][sel], last["pressure"][sel]
        rho_w = float((cfg.get("fluid") or {}).get("density", 1000.0))
        g = abs(float((cfg.get("gravity") or [-9.81])[-1]))
        pool = pos[:, -1] < z_lo
        surface = np.percentile(pos[pool, -1], 99) + 0.5 * rf.dx if pool.any() else None
        bottom = pos[:, -1] < pos[:, -1].min() + 0.5 * rf.dx
        p_bottom = float(np.mean(p[bottom]))
        # the pool's pressure gradient: least-squares slope of P against height over the water below
        # the layer, against rho_w g (a hydrostatic pool gives 1, whatever its surface)
        slope = None
        if pool.sum() > 2:
            slope = float(-np.polyfit(pos[pool, -1], p[pool], 1)[0] / (rho_w * g))
        p_hydro = float(np.mean(rho_w * g * (surface - pos[bottom, -1]))) if surface is not None else None
        return {
            "run": str(path), "dx": rf.dx, "dt": float(cfg["dt"]), "eps0": region["eps0"],
            "alpha": cfg.get("isph", {}).get("alpha", 0.01),
            "arrival_s": arrival, "body_arrival_s": body, "fraction_in_layer": frac_at,
            "drift_at_arrival": drift_arrival, "core_fill": core,
            "drift_min": float(vol.min()), "t_min": float(t[np.argmin(vol)]),
            "drift_max": float(vol.max()), "t_max": float(t[np.argmax(vol)]),
            "drift_end": float(vol[settled].mean()),
            "in_layer_end": float(frac[-1]),
            "bottom_pressure_Pa": p_bottom, "hydrostatic_Pa": p_hydro, "pool_gradient": slope,
            "max_speed": float(d["max_speed"].max()), "t_max_speed": float(t[np.argmax(d["max_speed"])]),
            "end_s": float(t[-1]), "finished": bool(t[-1] >= float(cfg["end_time"]) - 0.5 * float(cfg["dt"])),
            "options": options(cfg.get("isph") or {}),
            "wall_s": float(np.sum(d["wall_seconds"])) if "wall_seconds" in d else None,
        }


def options(isph):
    """Shifting / collisions / advection of a run, with the schema's defaults (config/isph.py), and eq 31's
    support in the ground where it is not the default's (isph.ground_density_support)."""
    shift = float(isph.get("shifting", 2.0))
    coll = float(isph.get("collision_distance", 0.8))
    on = lambda v: "off" if v == 0 else f"{v:g}"
    support = isph.get("ground_density_support", "particle")
    extra = "" if support == "particle" else f", eq 31 over the {support} support"
    return f"{on(shift)} / {on(coll)} / {isph.get('advection', 'pore')}{extra}"


def row(r):
    fmt = lambda v, f: "-" if v is None else format(v, f)
    seed = FREEFALL_ARRIVAL.get(round(float(r["eps0"]), 2))
    if not r["finished"]:  # the end state of a stopped run is its blow-up: no end numbers
        r = {**r, "drift_end": None, "in_layer_end": None, "hydrostatic_Pa": None, "pool_gradient": None}
    pressure = "-" if r["hydrostatic_Pa"] is None else (
        f"{r['bottom_pressure_Pa']:.0f} / {r['hydrostatic_Pa']:.0f} Pa, "
        f"{r['bottom_pressure_Pa'] / r['hydrostatic_Pa'] - 1:+.1%}")
    finished = "yes" if r["finished"] else f"stopped at {r['end_s']:.2f} s"
    c = r["core_fill"]
    core = "-" if c is None else f"{c[0]:.3f} ({c[1]:.3f}-{c[2]:.3f}) / {c[3]:.3f} ({c[4]:.3f}-{c[5]:.3f})"
    return (f"| {r['dx']:g} | {r['dt'] * 1e3:g} ms | {r['eps0']:g} | {r['alpha']:g} | {r['options']} | "
            f"{fmt(r['arrival_s'], '.3f')} ({fmt(seed, 'g')}) | {fmt(r['body_arrival_s'], '.3f')} | "
            f"{fmt(r['fraction_in_layer'], '.3f')} | {core} | "
            f"{fmt(r['drift_at_arrival'], '+.1%')} | {r['drift_min']:+.1%} ({r['t_min']:.2f} s) | "
            f"{r['drift_max']:+.1%} ({r['t_max']:.2f} s) | {fmt(r['drift_end'], '+.1%')} | "
            f"{fmt(r['in_layer_end'], '.1%')} | {pressure} | {fmt(r['pool_gradient'], '.3f')} | "
            f"{r['max_speed']:.2f} ({r['t_max_speed']:.2f} s) | {finished} | {fmt(r['wall_s'], '.0f')} |")


HEADER = ("| dx (m) | dt | eps0 | alpha | shifting / collisions / advection | arrival (s) (seed) | "
          "water body's arrival (s) | "
          "water in layer at arrival | layer core per pore volume 0.6-1.2 s: centres / slabs, mean (frames) | "
          "volume at arrival | "
          "volume lowest (t) | volume highest (t) | volume at end | in layer at end | "
          "bottom pressure vs hydrostatic | pool dP/dz / (rho_w g) | largest speed m/s (t) | finished | "
          "wall time (s) |")


def main(paths):
    print(HEADER)
    print("|" + "---|" * HEADER.count(" | ") + "---|")
    for path in paths:
        print(row(analyse(path)))


if __name__ == "__main__":
    main(sys.argv[1:])
