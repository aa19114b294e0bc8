"""Scene building: config geometry -> particle arrays (numpy), shared by both solver modes.

Particles sit on a lattice of spacing dx at cell centres, (i + 1/2) dx from the tank origin, so a
wall surface lies half a spacing from the nearest wall and water particles. Tank walls are
`tank.wall_layers` layers thick (default 3 >= r_e / dx = 2.4, so a particle at a wall has a full
kernel support), built on every side but the top when the tank is open. Each wall particle carries
a unit normal pointing into the fluid (used by slip walls and the wall pressure extrapolation).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .sph.kernels import SUPPORT_FACTOR

WATER, WALL, SOIL, AIR = 0, 1, 2, 3
KIND_NAMES = {WATER: "water", WALL: "wall", SOIL: "soil", AIR: "air"}


@dataclass
class Scene:
    dim: int
    dx: float
    position: np.ndarray  # (N, dim)
    kind: np.ndarray  # (N,) int8
    normal: np.ndarray  # (N, dim), zero for non-wall particles
    lo: np.ndarray  # neighbour-grid box
    hi: np.ndarray
    tank_size: np.ndarray
    markers: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.kind)

    @property
    def ids(self) -> np.ndarray:
        return np.arange(self.n, dtype=np.int32)

    def count(self, kind: int) -> int:
        return int((self.kind == kind).sum())


def lattice_in_box(lo, hi, dx) -> np.ndarray:
    """Cell-centred lattice points of spacing ~dx filling [lo, hi] (count per axis rounded)."""
    axes = []
    for a, b in zip(lo, hi):
        n = max(1, int(round((b - a) / dx)))
        step = (b - a) / n
        axes.append(a + (np.arange(n) + 0.5) * step)
    grids = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1)


def tank_walls(size, dx, layers, open_top=True):
    """Wall particles around the interior [0, size] and their inward unit normals."""
    dim = len(size)
    axes = []
    for ax, s in enumerate(size):
        n = max(1, int(round(s / dx)))
        step = s / n
        inner = (np.arange(n) + 0.5) * step
        below = -(np.arange(layers)[::-1] + 0.5) * dx
        above = s + (np.arange(layers) + 0.5) * dx
        if ax == dim - 1 and open_top:
            above = np.zeros(0)
        axes.append(np.concatenate([below, inner, above]))
    grids = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([g.ravel() for g in grids], axis=1)
    size_arr = np.asarray(size, dtype=float)
    interior = np.all((pts > 0) & (pts < size_arr), axis=1)
    pts = pts[~interior]
    nearest = np.clip(pts, 0.0, size_arr)
    normal = nearest - pts
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return pts, normal


def obstacle_particles(box_min, box_max, dx):
    """Wall particles filling a solid box, normals pointing out through the nearest face."""
    lo = np.asarray(box_min, float)
    hi = np.asarray(box_max, float)
    pts = lattice_in_box(lo, hi, dx)
    d_lo = pts - lo
    d_hi = hi - pts
    dist = np.concatenate([d_lo, d_hi], axis=1)
    face = np.argmin(dist, axis=1)
    dim = len(lo)
    normal = np.zeros_like(pts)
    idx = np.arange(len(pts))
    axis = face % dim
    sign = np.where(face < dim, -1.0, 1.0)
    normal[idx, axis] = sign
    return pts, normal


def remove_overlaps(keep: np.ndarray, others: np.ndarray, dist: float) -> np.ndarray:
    """Mask of `keep` points farther than `dist` from every point of `others`."""
    if len(others) == 0 or len(keep) == 0:
        return np.ones(len(keep), dtype=bool)
    from scipy.spatial import cKDTree  # noqa: PLC0415  (scene building only)

    d, _ = cKDTree(others).query(keep, k=1)
    return d > dist


def build_scene(cfg) -> Scene:
    """Particles for a validated Config (water blocks, tank walls, obstacles)."""
    dim, dx = cfg.dim, cfg.dx
    size = np.asarray(cfg.tank.size, dtype=float)
    layers = cfg.wall_layers()

    water = np.zeros((0, dim))
    for box in cfg.water:
        pts = lattice_in_box(box.min, box.max, dx)
        pts = pts[remove_overlaps(pts, water, 0.5 * dx)]
        water = np.concatenate([water, pts])

    wall, wall_n = tank_walls(size, dx, layers, cfg.tank.open_top)
    for box in cfg.obstacles:
        pts, nrm = obstacle_particles(box.min, box.max, dx)
        wall = np.concatenate([wall, pts])
        wall_n = np.concatenate([wall_n, nrm])
    water = water[remove_overlaps(water, wall, 0.5 * dx)]
    air = np.zeros((0, dim))
    for box in getattr(cfg, "air", []):  # air blocks displace the water they overlap
        pts = lattice_in_box(box.min, box.max, dx)
        pts = pts[remove_overlaps(pts, air, 0.5 * dx) & remove_overlaps(pts, wall, 0.5 * dx)]
        air = np.concatenate([air, pts])
    water = water[remove_overlaps(water, air, 0.5 * dx)]

    position = np.concatenate([water, wall])
    kind = np.concatenate([np.full(len(water), WATER, np.int8), np.full(len(wall), WALL, np.int8)])
    normal = np.concatenate([np.zeros_like(water), wall_n])
    position, normal = np.concatenate([position, air]), np.concatenate([normal, np.zeros_like(air)])
    kind = np.concatenate([kind, np.full(len(air), AIR, np.int8)])

    r_e = SUPPORT_FACTOR * dx
    lo = -(layers + 1) * dx * np.ones(dim)
    hi = size + (layers + 1) * dx
    hi[-1] = size[-1] + max(0.5 * size[-1], 4 * r_e)
    return Scene(dim=dim, dx=dx, position=position, kind=kind, normal=normal, lo=lo, hi=hi, tank_size=size)


def describe(scene: Scene) -> str:
    parts = [f"{scene.count(k)} {name}" for k, name in KIND_NAMES.items() if scene.count(k)]
    return f"{scene.n} particles ({', '.join(parts)}), dim {scene.dim}, dx {scene.dx:g} m"
