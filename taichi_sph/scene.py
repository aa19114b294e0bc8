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

from .kinds import AIR, KIND_NAMES, SOIL, WALL, WATER  # noqa: F401  (the solvers import the kinds from here)
from .sph.support import SUPPORT_FACTOR
from .sph.wall_motion import Motion


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
    markers: dict = field(default_factory=dict)  # soil markers: position, eps0, d50, volume (M,)
    velocity: np.ndarray | None = None  # (N, dim) initial velocity; None: all at rest
    period: tuple = ()  # period L per axis, 0.0 where not periodic (empty: no periodic axis)
    inflow_rows: list = field(default_factory=list)  # per inflow source, its rows of reserve ids (wcsph/inflow.py)
    #: per particle, the index into `motions` of the moving obstacle it belongs to, -1 for all else
    body: np.ndarray | None = None
    #: prescribed motion of each moving obstacle (sph.wall_motion.Motion)
    motions: list = field(default_factory=list)
    #: per particle, the packing of the water block it was placed in: the lattice's count over the
    #: block's pore volume in particles, porosity * volume / dx^dim (the rounding of the count per axis;
    #: 1.05 for the permeameter's plug at dx 10 mm, 42 particles for 40); 1 for all else. None: all 1
    packing: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.kind)

    @property
    def ids(self) -> np.ndarray:
        return np.arange(self.n, dtype=np.int32)

    def count(self, kind: int) -> int:
        return int((self.kind == kind).sum())

    def periods(self) -> tuple:
        """Period L of each axis, 0.0 where the axis is not periodic (for sph.operators.rel)."""
        return tuple(float(v) for v in self.period) if self.period else (0.0,) * self.dim


def lattice_in_box(lo, hi, dx) -> np.ndarray:
    """Cell-centred lattice points of spacing ~dx filling [lo, hi] (count per axis rounded)."""
    axes = []
    for a, b in zip(lo, hi):
        n = max(1, int(round((b - a) / dx)))
        step = (b - a) / n
        axes.append(a + (np.arange(n) + 0.5) * step)
    grids = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1)


def tank_walls(size, dx, layers, open_top=True, periodic=()):
    """Wall particles around the interior [0, size] and their inward unit normals; none on the two
    sides of a periodic axis."""
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
        if ax in periodic:
            below = above = np.zeros(0)
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


def spanned_periodic_axes(lo, hi, size, periodic) -> list:
    """Periodic axes a box spans from side to side: it runs on through the wrap and has no faces there."""
    out = []
    for ax in periodic:
        tol = 1e-9 * max(1.0, float(size[ax]))
        if lo[ax] <= tol and hi[ax] >= float(size[ax]) - tol:
            out.append(ax)
    return out


def obstacle_particles(box_min, box_max, dx, periodic=(), size=None):
    """Wall particles filling a solid box, normals pointing out through the nearest face (none across a
    periodic axis the box spans, `spanned_periodic_axes`)."""
    lo = np.asarray(box_min, float)
    hi = np.asarray(box_max, float)
    pts = lattice_in_box(lo, hi, dx)
    d_lo = pts - lo
    d_hi = hi - pts
    for ax in spanned_periodic_axes(lo, hi, size, periodic):
        d_lo[:, ax] = d_hi[:, ax] = np.inf
    dist = np.concatenate([d_lo, d_hi], axis=1)
    dim = len(lo)
    # the outward normal of the nearest face; at a corner or an edge (equally near faces) the mean of
    # their normals, normalised (the bisector: a corner particle pushes fluid away from both faces)
    nearest = dist <= dist.min(axis=1, keepdims=True) + 1e-9 * dx
    normal = (nearest[:, dim:].astype(float) - nearest[:, :dim].astype(float))
    # equally near opposite faces (the middle of an odd-thickness slab) cancel: the first nearest face
    face = np.argmin(dist, axis=1)
    lone = np.linalg.norm(normal, axis=1) == 0.0
    normal[lone] = 0.0
    normal[lone, face[lone] % dim] = np.where(face[lone] < dim, -1.0, 1.0)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return pts, normal


def porous_lattice(lo, hi, dx, porosity: float) -> np.ndarray:
    """Cell-centred lattice filling [lo, hi] with water at the given porosity: about
    porosity * volume / dx^dim points. Per axis the count is rounded down or up (spacing near
    dx / porosity^(1/dim)), choosing the combination whose total is closest to that target."""
    if porosity >= 1.0:
        return lattice_in_box(lo, hi, dx)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    dim = len(lo)
    s = dx * porosity ** (-1.0 / dim)
    target = porosity * np.prod(hi - lo) / dx**dim
    choices = [sorted({max(1, int(np.floor((b - a) / s))), max(1, int(np.ceil((b - a) / s)))}) for a, b in zip(lo, hi)]
    best = None
    for counts in np.array(np.meshgrid(*choices, indexing="ij")).reshape(dim, -1).T:
        err = abs(np.prod(counts) - target)
        if best is None or err < best[0]:
            best = (err, counts)
    axes = [a + (np.arange(n) + 0.5) * (b - a) / n for a, b, n in zip(lo, hi, best[1])]
    grids = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1)


def marker_lattice(lo, hi, spacing, nodes: bool) -> np.ndarray:
    """Marker points in [lo, hi]: cell centres, or nodes including faces and corners."""
    if not nodes:
        return lattice_in_box(lo, hi, spacing)
    axes = []
    for a, b in zip(lo, hi):
        n = max(1, int(round((b - a) / spacing)))
        axes.append(np.linspace(a, b, n + 1))
    grids = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1)


def region_bounds(reg, dim: int, tank_size, margin: float):
    """Bounding box of a soil region, pushed `margin` into the walls on every side where it meets the
    tank: the ground runs on into the wall, so water next to a wall keeps the ground's porosity
    (markers stopping at the wall face would give eps = 1 along every wall, a free channel)."""
    size = np.asarray(tank_size, float)
    if reg.shape == "box":
        lo, hi = np.asarray(reg.min, float), np.asarray(reg.max, float)
    else:
        lo = np.array([reg.toe[0]] + ([0.0] if dim == 3 else []) + [reg.bottom])
        hi = np.array([reg.toe[1]] + ([size[1]] if dim == 3 else []) + [reg.top])
    tol = 1e-9 * max(1.0, float(size.max()))
    margin = np.broadcast_to(np.asarray(margin, float), lo.shape)
    lo = np.where(lo <= tol, lo - margin, lo)
    hi = np.where(hi >= size - tol, hi + margin, hi)
    return lo, hi


def inside_region(pts: np.ndarray, reg, dim: int, tank_size, margin: float = 0.0) -> np.ndarray:
    """Mask of points inside a soil region (box or mound, with its extension into the walls), faces
    included."""
    tol = 1e-9
    lo, hi = region_bounds(reg, dim, tank_size, margin)
    mask = np.all((pts >= lo - tol) & (pts <= hi + tol), axis=1)
    if reg.shape == "mound":
        x = pts[:, 0]
        z = np.maximum(pts[:, -1], reg.bottom)
        frac = (z - reg.bottom) / (reg.top - reg.bottom)
        left = reg.toe[0] + frac * (reg.crest[0] - reg.toe[0])
        right = reg.toe[1] + frac * (reg.crest[1] - reg.toe[1])
        mx = float(np.ravel(margin)[0])
        left = np.where(left <= tol, left - mx, left)
        right = np.where(right >= tank_size[0] - tol, right + mx, right)
        mask &= (x >= left - tol) & (x <= right + tol)
    return mask


def build_markers(cfg) -> dict:
    """Soil markers (seed 000 section 4): fixed reference points, never SPH particles. Each carries
    its region's eps0 and D50 and the volume V_j of eq 32 (spacing^dim). A later region replaces the
    markers of earlier ones inside it. Regions that meet the tank run on into its walls by the wall
    thickness. Empty dict when the config has no soil."""
    soil = getattr(cfg, "soil", None)  # porous ground of mode isph
    if soil is None or not soil.regions:
        return {}
    dim = cfg.dim
    s = soil.marker_spacing or cfg.dx
    nodes = soil.lattice == "nodes"
    size = np.asarray(cfg.tank.size, float)
    # into the walls, but not across a periodic side (its images continue the ground there)
    margin = np.array([0.0 if ax in cfg.tank.periodic else cfg.wall_layers() * cfg.dx for ax in range(dim)])
    pos = np.zeros((0, dim))
    eps0 = np.zeros(0)
    d50 = np.zeros(0)
    for reg in soil.regions:
        lo, hi = region_bounds(reg, dim, size, 0.0)
        pts = marker_lattice(lo, hi, s, nodes)
        # the same lattice continued into the walls where the region meets them
        elo, ehi = region_bounds(reg, dim, size, margin)
        steps = [(b - a) / max(1, int(round((b - a) / s))) for a, b in zip(lo, hi)]
        ext = []
        for ax in range(dim):
            below = pts[:, ax].min() - steps[ax] * np.arange(1, int(np.ceil((lo[ax] - elo[ax]) / steps[ax] - 1e-9)) + 1)
            above = pts[:, ax].max() + steps[ax] * np.arange(1, int(np.ceil((ehi[ax] - hi[ax]) / steps[ax] - 1e-9)) + 1)
            ext.append(np.concatenate([below[::-1], np.unique(pts[:, ax]), above]))
        grids = np.meshgrid(*ext, indexing="ij")
        pts = np.stack([g.ravel() for g in grids], axis=1)
        pts = pts[inside_region(pts, reg, dim, size, margin)]
        if len(pos):
            keep = ~inside_region(pos, reg, dim, size, margin)
            pos, eps0, d50 = pos[keep], eps0[keep], d50[keep]
        pos = np.concatenate([pos, pts])
        eps0 = np.concatenate([eps0, np.full(len(pts), reg.eps0)])
        d50 = np.concatenate([d50, np.full(len(pts), reg.d50)])
    pos, eps0, d50 = periodic_images(pos, [eps0, d50], size, cfg.tank.periodic, SUPPORT_FACTOR * cfg.dx)
    return {"position": pos, "eps0": eps0, "d50": d50, "volume": np.full(len(pos), s**dim)}


def periodic_images(pos: np.ndarray, values: list, size, periodic, reach: float):
    """Fixed points plus their images shifted by -L and +L along each periodic axis, as far as `reach`
    beyond each periodic side (markers are never moved, so their images are added once and the
    porosity sum needs no minimum image). Returns the points and each array of `values` extended alike."""
    for ax in periodic:
        L = float(size[ax])
        low = pos[:, ax] < reach
        high = pos[:, ax] >= L - reach
        shift = np.zeros(pos.shape[1])
        shift[ax] = L
        values = [np.concatenate([v, v[low], v[high]]) for v in values]
        pos = np.concatenate([pos, pos[low] + shift, pos[high] - shift])
    return (pos, *values)


#: pairs up to which `remove_overlaps` compares every pair with NumPy instead of building a k-d tree:
#: importing scipy.spatial takes ~0.3 s, a tenth of a small run's start-up, and a scene calls it two or
#: three times; 1e6 pairs take ~35 ms this way (2-core AMD EPYC; the shipped 2D tank, 1200 water
#: particles against 378 wall particles, 0.45e6)
BRUTE_FORCE_PAIRS = 1_000_000


def remove_overlaps(keep: np.ndarray, others: np.ndarray, dist: float) -> np.ndarray:
    """Mask of `keep` points farther than `dist` from every point of `others`."""
    if len(others) == 0 or len(keep) == 0:
        return np.ones(len(keep), dtype=bool)
    if len(keep) * len(others) <= BRUTE_FORCE_PAIRS:  # all pairs at once: at most ~24 MB in 3D
        d2 = ((keep[:, None, :] - others[None, :, :]) ** 2).sum(axis=-1).min(axis=1)
        return np.sqrt(d2) > dist
    from scipy.spatial import cKDTree  # noqa: PLC0415  (scene building only)

    d, _ = cKDTree(others).query(keep, k=1)
    return d > dist


def soil_particles(cfg, wall: np.ndarray) -> np.ndarray:
    """Soil particles of mode wcsph_biot: the cell-centred lattice of spacing dx inside each soil block
    (box or mound, faces included), without repeats where blocks overlap and clear of wall particles.
    They overlap water and air: the fluid in the soil's pores is the fluid particles at the same places."""
    dim, dx = cfg.dim, cfg.dx
    size = np.asarray(cfg.tank.size, float)
    soil = np.zeros((0, dim))
    for blk in getattr(cfg, "soil_blocks", []):
        lo, hi = blk.bounds(dim, size)
        if blk.shape == "box":
            pts = lattice_in_box(lo, hi, dx)
        else:  # the tank's lattice, cut by the trapezoid
            pts = lattice_in_box(np.zeros(dim), size, dx)
            pts = pts[inside_region(pts, blk, dim, size)]
        pts = pts[remove_overlaps(pts, soil, 0.5 * dx) & remove_overlaps(pts, wall, 0.5 * dx)]
        soil = np.concatenate([soil, pts])
    return soil


def soil_block_index(cfg, pts: np.ndarray) -> np.ndarray:
    """Index into cfg.soil_blocks of the block each soil point belongs to: the first block that holds
    it (the one `soil_particles` took it from: later blocks skip points of earlier ones); -1 for none."""
    size = np.asarray(cfg.tank.size, float)
    out = np.full(len(pts), -1, np.int64)
    for k, blk in enumerate(getattr(cfg, "soil_blocks", [])):
        if blk.shape == "box":  # faces included, as lattice_in_box
            lo, hi = np.asarray(blk.min, float), np.asarray(blk.max, float)
            mask = np.all((pts >= lo - 1e-9) & (pts <= hi + 1e-9), axis=1)
        else:
            mask = inside_region(pts, blk, cfg.dim, size)
        out[mask & (out < 0)] = k
    return out


def cut_to_soil(cfg, box, pts: np.ndarray) -> np.ndarray:
    """A fluid block's (config.geometry.SoilSideBlock) lattice points `pts` kept by its `inside_soil` (the
    pores only: its points inside soil blocks; not empty, a config check) or `outside_soil` (the open space
    only); all of them without either (mode isph rejects both)."""
    if box.inside_soil:
        return pts[soil_block_index(cfg, pts) >= 0]
    if box.outside_soil:
        return pts[soil_block_index(cfg, pts) < 0]
    return pts


def build_scene(cfg) -> Scene:
    """Particles for a validated Config (water blocks, tank walls, obstacles)."""
    dim, dx = cfg.dim, cfg.dx
    size = np.asarray(cfg.tank.size, dtype=float)
    layers = cfg.wall_layers()

    water = np.zeros((0, dim))
    water_v = np.zeros((0, dim))
    water_packing = np.zeros(0)
    for box in cfg.water:
        # water in ground of porosity eps fills its pores: spacing dx / eps^(1/dim), mass unchanged
        lattice = porous_lattice(box.min, box.max, dx, box.porosity)
        pores = box.porosity * float(np.prod(np.asarray(box.max, float) - np.asarray(box.min, float))) / dx**dim
        pts = cut_to_soil(cfg, box, lattice)
        pts = pts[box.below_table(pts)]  # a water table (`water[k].table`) cuts the block's top
        if box.jitter > 0:
            pts = pts + np.random.default_rng(len(water)).uniform(-box.jitter, box.jitter, pts.shape) * dx
        keep = remove_overlaps(pts, water, 0.5 * dx)
        water = np.concatenate([water, pts[keep]])
        water_v = np.concatenate([water_v, block_velocity(box, pts[keep], size)])
        water_packing = np.concatenate([water_packing, np.full(int(keep.sum()), len(lattice) / max(pores, 1e-300))])

    wall, wall_n = tank_walls(size, dx, layers, cfg.tank.open_top, tuple(cfg.tank.periodic))
    wall_body = np.full(len(wall), -1, np.int32)
    motions = []
    sweep_lo, sweep_hi = np.zeros(dim), size.copy()  # what moving obstacles sweep until end_time
    for box in cfg.obstacles:
        pts, nrm = obstacle_particles(box.min, box.max, dx, tuple(cfg.tank.periodic), size)
        body = -1
        if box.motion is not None:
            body = len(motions)
            motions.append(Motion.from_config(box.motion))
            d_lo, d_hi = motions[-1].reach(cfg.end_time)
            sweep_lo = np.minimum(sweep_lo, np.asarray(box.min, float) + d_lo)
            sweep_hi = np.maximum(sweep_hi, np.asarray(box.max, float) + d_hi)
        wall = np.concatenate([wall, pts])
        wall_n = np.concatenate([wall_n, nrm])
        wall_body = np.concatenate([wall_body, np.full(len(pts), body, np.int32)])
    keep = remove_overlaps(water, wall, 0.5 * dx)
    water, water_v, water_packing = water[keep], water_v[keep], water_packing[keep]
    air = np.zeros((0, dim))
    for box in getattr(cfg, "air", []):  # air blocks displace the water they overlap
        pts = cut_to_soil(cfg, box, lattice_in_box(box.min, box.max, dx))
        pts = pts[remove_overlaps(pts, air, 0.5 * dx) & remove_overlaps(pts, wall, 0.5 * dx)]
        air = np.concatenate([air, pts])
    keep = remove_overlaps(water, air, 0.5 * dx)
    water, water_v, water_packing = water[keep], water_v[keep], water_packing[keep]

    position = np.concatenate([water, wall])
    kind = np.concatenate([np.full(len(water), WATER, np.int8), np.full(len(wall), WALL, np.int8)])
    normal = np.concatenate([np.zeros_like(water), wall_n])
    position, normal = np.concatenate([position, air]), np.concatenate([normal, np.zeros_like(air)])
    kind = np.concatenate([kind, np.full(len(air), AIR, np.int8)])
    soil = soil_particles(cfg, wall)
    position, normal = np.concatenate([position, soil]), np.concatenate([normal, np.zeros_like(soil)])
    kind = np.concatenate([kind, np.full(len(soil), SOIL, np.int8)])
    inflow_rows = []
    if getattr(cfg, "inflow", []):  # reserve water of the river inflow, held out until released (wcsph/inflow.py)
        reserve, rows = inflow_particles(cfg, wall, position[kind != WALL])
        inflow_rows = [[row + len(position) for row in src] for src in rows]
        position, normal = np.concatenate([position, reserve]), np.concatenate([normal, np.zeros_like(reserve)])
        kind = np.concatenate([kind, np.full(len(reserve), WATER, np.int8)])

    r_e = SUPPORT_FACTOR * dx
    lo = -(layers + 1) * dx * np.ones(dim)
    hi = size + (layers + 1) * dx
    hi[-1] = size[-1] + max(0.5 * size[-1], 4 * r_e)
    # moving obstacles stay inside the neighbour grid over the whole run
    lo = np.minimum(lo, sweep_lo - (layers + 1) * dx)
    hi = np.maximum(hi, sweep_hi + (layers + 1) * dx)
    period = tuple(float(size[ax]) if ax in cfg.tank.periodic else 0.0 for ax in range(dim))
    for ax in cfg.tank.periodic:
        lo[ax], hi[ax] = 0.0, size[ax]
    body = None
    if motions:
        body = np.full(len(position), -1, np.int32)
        body[len(water): len(water) + len(wall)] = wall_body  # walls follow the water in `position`
    packing = np.ones(len(position))
    packing[: len(water)] = water_packing
    velocity = None
    if np.any(water_v != 0.0):
        velocity = np.zeros_like(position)
        velocity[: len(water_v)] = water_v
    return Scene(dim=dim, dx=dx, position=position, kind=kind, normal=normal, lo=lo, hi=hi, tank_size=size,
                 markers=build_markers(cfg), velocity=velocity, period=period, inflow_rows=inflow_rows,
                 body=body, motions=motions, packing=packing)


def inflow_particles(cfg, wall: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Reserve particles of every inflow box (positions) and, per inflow, the rows of indices into them,
    lowest row first (wcsph/inflow.py releases them row by row). Points within dx / 2 of a wall or
    another particle are left out."""
    dx = cfg.dx
    pts_all = np.zeros((0, cfg.dim))
    rows = []
    for src in cfg.inflow:
        pts = lattice_in_box(src.min, src.max, dx)
        pts = pts[remove_overlaps(pts, wall, 0.5 * dx) & remove_overlaps(pts, others, 0.5 * dx)
                  & remove_overlaps(pts, pts_all, 0.5 * dx)]
        level = np.round((pts[:, -1] - pts[:, -1].min()) / dx).astype(np.int64) if len(pts) else np.zeros(0, int)
        base = len(pts_all)
        rows.append([base + np.nonzero(level == k)[0] for k in np.unique(level)])
        pts_all = np.concatenate([pts_all, pts])
    return pts_all, rows


def taylor_green_velocity(pts: np.ndarray, size, scale: float) -> np.ndarray:
    """2D Taylor-Green vortex in the doubly periodic box [0, Lx) x [0, Ly):
    u = U sin(kx x) cos(ky y), v = -U (kx / ky) cos(kx x) sin(ky y), k = 2 pi / L (divergence free;
    its kinetic energy decays as exp(-2 nu (kx^2 + ky^2) t))."""
    kx, ky = 2.0 * np.pi / float(size[0]), 2.0 * np.pi / float(size[1])
    x, y = pts[:, 0], pts[:, 1]
    return np.stack([scale * np.sin(kx * x) * np.cos(ky * y),
                     -scale * (kx / ky) * np.cos(kx * x) * np.sin(ky * y)], axis=1)


def block_velocity(box, pts: np.ndarray, size) -> np.ndarray:
    """Initial velocity of a water block's particles (`water[].initial_velocity`)."""
    if getattr(box, "initial_velocity", "rest") == "taylor_green":
        return taylor_green_velocity(pts, size, box.velocity_scale)
    return np.zeros_like(pts)


def describe(scene: Scene) -> str:
    parts = [f"{scene.count(k)} {name}" for k, name in KIND_NAMES.items() if scene.count(k)]
    text = f"{scene.n} particles ({', '.join(parts)}), dim {scene.dim}, dx {scene.dx:g} m"
    if scene.markers:
        text += f", {len(scene.markers['position'])} soil markers"
    return text
