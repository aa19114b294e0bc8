"""Initial state of mode wcsph_biot (numpy, before any kernel runs): densities, masses, velocities
and the depth of wall particles behind the wall surface.

- Pressure at start: the weight of the fluid above each particle in its lattice column,
  p_i = |g| dx (sum_{j above i} rho0_j + rho0_i / 2) (gauge, the ambient p0 acts on the surface). Air
  takes the density of the gas EOS (eq 39-40) at that pressure, as the seed sets its bubble from the
  100 kPa overburden plus the water above it; water takes the Tait density (eq 41) at that pressure
  (`initial_density: hydrostatic`) or rho0 (`uniform`, the seed's collapse cases).
- `water[k].start_head`: that block starts hydrostatic under the given level instead (a plenum fed
  from a reservoir beside it).
- Mass m_i = rho_i dx^dim, so that every particle starts with the lattice volume dx^dim.
- `release_velocity: right_face`: the rightmost particle column of each water block moves along +x
  with sqrt(2 |g| (H - y)), H the block top (seed section 3.1).
- `wcsph.soil.start_from`: the soil's positions, stress, plastic strain and density from an earlier
  run (stage.py); the scene's soil positions are replaced in place.
"""

from __future__ import annotations

import numpy as np

from ..scene import AIR, SOIL, WALL, WATER, soil_block_index, spanned_periodic_axes
from . import eos
from .soil import geostatic_stress
from .stage import apply_stage, load_stage


def column_pressure(position: np.ndarray, rho0: np.ndarray, dx: float, g_down: float) -> np.ndarray:
    """Hydrostatic gauge pressure of each point from the points above it in the same lattice column
    (columns binned by floor(horizontal / dx)); rho0 is each point's reference density."""
    n = len(position)
    if n == 0 or g_down <= 0.0:
        return np.zeros(n)
    horizontal = np.floor(position[:, :-1] / dx).astype(np.int64)
    _, column = np.unique(horizontal, axis=0, return_inverse=True)
    column = column.reshape(-1)
    order = np.lexsort((-position[:, -1], column))  # by column, top first
    weight = rho0[order] * g_down * dx
    total = np.cumsum(weight)
    col_sorted = column[order]
    first = np.r_[0, np.nonzero(np.diff(col_sorted))[0] + 1]
    start = np.repeat(np.r_[0.0, total[first[1:] - 1]], np.diff(np.r_[first, n]))
    above = total - weight - start
    p = np.empty(n)
    p[order] = above + 0.5 * weight
    return p


def head_pressure(cfg, position: np.ndarray, kind: np.ndarray, p: np.ndarray, rho0: np.ndarray,
                  g_down: float) -> None:
    """`water[k].start_head` (in place): water particles of such a block (the first block whose box holds
    them, faces included, as the blocks are filled) start at rho0 g (start_head - height)."""
    taken = kind != WATER
    for blk in cfg.water:
        lo, hi = np.asarray(blk.min, float), np.asarray(blk.max, float)
        inside = np.all((position >= lo - 1e-9) & (position <= hi + 1e-9), axis=1) & ~taken
        if getattr(blk, "inside_soil", False):  # that block filled only the soil's pores
            inside &= soil_block_index(cfg, position) >= 0
        elif getattr(blk, "outside_soil", False):
            inside &= soil_block_index(cfg, position) < 0
        inside &= blk.below_table(position)
        if blk.start_head is not None:
            p[inside] = rho0[inside] * g_down * (blk.start_head - position[inside, -1])
        taken |= inside


def wall_depth(position: np.ndarray, kind: np.ndarray, tank_size, obstacles, periodic=()) -> np.ndarray:
    """d_B of eq 51 for wall particles (0 for others): the distance of a tank-wall particle from the
    tank interior [0, size], or of an obstacle particle from the nearest face of its obstacle (an
    obstacle that spans a periodic axis has no faces across it, scene.spanned_periodic_axes)."""
    size = np.asarray(tank_size, float)
    depth = np.zeros(len(position))
    wall = kind == WALL
    p = position[wall]
    d = np.linalg.norm(p - np.clip(p, 0.0, size), axis=1)
    inside = d == 0.0
    for box in obstacles:
        lo, hi = np.asarray(box.min, float), np.asarray(box.max, float)
        within = inside & np.all((p >= lo) & (p <= hi), axis=1)
        gap = np.minimum(p[within] - lo, hi - p[within])
        gap[:, spanned_periodic_axes(lo, hi, size, periodic)] = np.inf
        face = gap.min(axis=1)
        d[within] = face
    depth[wall] = d
    return depth


def initial_state(cfg, scene, materials: dict) -> dict:
    """Density, mass and velocity of every particle (walls: rho0 of water, no mass used, at rest).

    `materials` maps a kind to its (rho0, B, gamma). Returns arrays `density`, `mass`, `velocity`,
    `pressure` (gauge) and `wall_depth`."""
    dim, dx = cfg.dim, cfg.dx
    g = np.asarray(cfg.gravity_vector(), float)
    kind = scene.kind
    fluid = (kind == WATER) | (kind == AIR)
    for rows in scene.inflow_rows:  # reserve water of an inflow weighs on nothing before its release
        for row in rows:
            fluid[row] = False
    rho_ref = np.full(scene.n, materials[WATER][0])
    for k, (rho0, _, _) in materials.items():
        rho_ref[kind == k] = rho0
    p = np.zeros(scene.n)
    p[fluid] = column_pressure(scene.position[fluid], rho_ref[fluid], dx, -g[-1])
    head_pressure(cfg, scene.position, kind, p, rho_ref, -g[-1])
    rho = rho_ref.copy()
    for k, (rho0, b, gamma) in materials.items():
        sel = kind == k
        if k == WATER and cfg.wcsph.initial_density == "uniform":
            p[sel] = 0.0
            continue
        rho[sel] = eos.density_np(p[sel], rho0, b, gamma)
    mass = rho * dx**dim
    vel = np.zeros((scene.n, dim)) if scene.velocity is None else np.array(scene.velocity, float)
    if cfg.wcsph.release_velocity == "right_face":
        g_down = max(-g[-1], 0.0)
        x = scene.position
        for box in cfg.water:
            lo, hi = np.asarray(box.min), np.asarray(box.max)
            inside = (kind == WATER) & np.all((x >= lo - 1e-12) & (x <= hi + 1e-12), axis=1)
            if not inside.any():
                continue
            face = inside & (x[:, 0] > x[inside, 0].max() - 0.5 * dx)
            vel[face, 0] = np.sqrt(2.0 * g_down * np.maximum(hi[-1] - x[face, -1], 0.0))
    out = {"density": rho, "mass": mass, "velocity": vel, "pressure": p,
           "wall_depth": wall_depth(scene.position, kind, cfg.tank.size, cfg.obstacles, tuple(cfg.tank.periodic))}
    out["stress"] = soil_start(cfg, scene, rho, mass, materials[WATER][0])
    stage = load_stage(cfg, scene)
    if stage is not None:  # two-stage run: the soil of the earlier stage (stage.py)
        out["plastic_strain"] = apply_stage(stage, scene, rho, out["stress"])
    excess_pore_pressure(cfg, scene, p, rho, mass, out["stress"], materials[WATER], vel)
    return out


def excess_pore_pressure(cfg, scene, p, rho, mass, stress, water, vel) -> None:
    """`wcsph.soil.initial_excess_pressure` (in place): u_e = A sin(pi (y - bottom) / (top - bottom)) added
    to the pressure of water particles that share a soil particle's place (their density from the Tait
    EOS at the new pressure) and taken from the soil's effective stress (vertical u_e, horizontal K0 u_e).
    The soil starts moving as the consolidating layer does at t = 0+ (Terzaghi's quasi-static state, seed
    002 eq 55): the water seeps at Darcy's q = -(k / gamma_w) d u_e / dy relative to the skeleton, and with
    the layer laterally confined over an impermeable base the mixture's flux n v_f + (1 - n) v_s (the
    velocity the water particles carry) is zero, so the skeleton settles at v_s = -q = (k / gamma_w)
    d u_e / dy and the water particles stay at rest (with `wcsph.soil.pore_water: pore_volume` they carry
    the pore velocity v_f = -(1 - n) / n v_s). Started from rest instead, the layer reaches that
    speed through an undrained compression wave of amplitude ~rho c v_s (with the default sound speed,
    0.2-0.4 u0 in configs/consolidation.yaml, decaying over ~0.1 s)."""
    ex = cfg.wcsph.soil.initial_excess_pressure
    kind = scene.kind
    if ex is None or not (kind == SOIL).any():
        return
    y = scene.position[:, -1]
    u = np.where((y >= ex.bottom) & (y <= ex.top),
                 ex.amplitude * np.sin(np.pi * (y - ex.bottom) / (ex.top - ex.bottom)), 0.0)
    soil = np.nonzero(kind == SOIL)[0]
    wat = np.nonzero(kind == WATER)[0]
    if len(wat):
        from scipy.spatial import cKDTree  # start state only

        d, _ = cKDTree(scene.position[soil]).query(scene.position[wat], k=1)
        wet = wat[d < 0.5 * cfg.dx]
        # the settlement rate at t = 0+ (not for a held skeleton, which keeps its place)
        if not cfg.wcsph.soil.fixed and not any(b.fixed for b in cfg.soil_blocks):
            g_abs = float(np.linalg.norm(cfg.gravity_vector()))

            def settling(yy):
                arg = np.pi * (yy - ex.bottom) / (ex.top - ex.bottom)
                du_dy = ex.amplitude * np.pi / (ex.top - ex.bottom) * np.cos(arg)
                inside = (yy >= ex.bottom) & (yy <= ex.top)
                return np.where(inside, cfg.wcsph.soil.permeability / (water[0] * g_abs) * du_dy, 0.0)

            vel[soil, -1] = settling(y[soil])
            if cfg.wcsph.soil.pore_water == "pore_volume":
                # the water particles carry the pore velocity: n v_f + (1 - n) v_s = 0
                n0 = cfg.wcsph.soil.porosity
                vel[wet, -1] = -(1.0 - n0) / n0 * settling(y[wet])
        p[wet] += u[wet]
        rho[wet] = eos.density_np(p[wet], *water)
        mass[wet] = rho[wet] * cfg.dx**cfg.dim
    sp = cfg.wcsph.soil
    k0 = sp.k0 if sp.k0 is not None else sp.poisson / (1.0 - sp.poisson)
    dim = cfg.dim
    for a in range(dim - 1):
        stress[soil, a, a] -= k0 * u[soil]
    stress[soil, dim - 1, dim - 1] -= u[soil]


def soil_start(cfg, scene, rho: np.ndarray, mass: np.ndarray, rho_w: float) -> np.ndarray:
    """Soil particles (in place): density (1 - n0) rho_s and mass (1 - n0) rho_s dx^dim; returns the
    effective stress of every particle (N, dim, dim; zero but for soil) at the K0 start: the vertical
    effective stress is the weight of the soil above in its lattice column, buoyant ((1 - n0)
    (rho_s - rho_w) g per unit volume, i.e. gamma_sat - gamma_w) where a water particle shares the soil
    particle's place and dry ((1 - n0) rho_s g) where not; horizontal K0 times that (K0 default
    nu / (1 - nu))."""
    dim, dx = cfg.dim, cfg.dx
    kind = scene.kind
    soil = kind == SOIL
    stress = np.zeros((scene.n, dim, dim))
    if not soil.any():
        return stress
    sp = cfg.wcsph.soil
    rho_s = (1.0 - sp.porosity) * sp.grain_density
    rho[soil] = rho_s
    mass[soil] = rho_s * dx**dim
    pos = scene.position[soil]
    water = scene.position[kind == WATER]
    submerged = np.zeros(len(pos), bool)
    if len(water):
        from scipy.spatial import cKDTree  # start state only

        d, _ = cKDTree(water).query(pos, k=1)
        submerged = d < 0.5 * dx
    unit = (1.0 - sp.porosity) * (sp.grain_density - rho_w * submerged)
    g_down = -float(np.asarray(cfg.gravity_vector())[-1])
    sigma_v = column_pressure(pos, unit, dx, g_down)
    k0 = sp.k0 if sp.k0 is not None else sp.poisson / (1.0 - sp.poisson)
    stress[soil] = geostatic_stress(sigma_v, k0, dim)
    return stress
