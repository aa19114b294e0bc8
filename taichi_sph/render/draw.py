"""The PyVista scene of one run: particles coloured by a field, walls, soil markers, colour bar,
time label, camera presets; one Plotter reused for every frame; movies through imageio.

Coordinates: the vertical axis is drawn upwards. A 2D run (x, y) is drawn in the plane (x, 0, y)
of a 3D scene, so that in both cases the picture's vertical is the run's vertical and the `front`
view shows x to the right. Views are orthographic (parallel projection), which makes the particle
size on screen exact: a particle is drawn as a sphere of diameter dx in pixels at the view's scale.
"""

from __future__ import annotations

import math

import numpy as np

from .offscreen import configure_env

WALL = 1

#: view direction (from the camera towards the scene) and up vector of each preset, in drawing
#: coordinates (z up)
CAMERAS = {
    "front": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "side": ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "iso": ((-1.0, 1.0, -0.8), (0.0, 0.0, 1.0)),
}

KIND_COLOURS = ["#1f77b4", "#9e9e9e", "#a0522d", "#e0e0ff"]  # water, wall, soil, air
BAR_FRACTION = 0.22  # share of the picture's width kept free for the colour bar


def round16(n: int) -> int:
    """Round a pixel count up to a multiple of 16 (video encoders work on 16x16 blocks)."""
    return max(16, math.ceil(int(n) / 16.0) * 16)


def embed(pos: np.ndarray) -> np.ndarray:
    """Run coordinates -> drawing coordinates (2D: (x, y) -> (x, 0, y))."""
    pos = np.asarray(pos, dtype=float)
    if pos.shape[1] == 3:
        return pos
    out = np.zeros((pos.shape[0], 3))
    out[:, 0] = pos[:, 0]
    out[:, 2] = pos[:, 1]
    return out


class Drawing:
    """One plotter for a sequence of frames.

    bounds: (lo, hi) of the domain in run coordinates (fixes the camera for all frames);
    clim: colour range, or None for an automatic range per frame; categorical: colour by kind.
    """

    def __init__(self, *, dim: int, dx: float, size: tuple[int, int], camera: str, walls: str, title: str,
                 clim: tuple[float, float] | None, categorical: bool, bounds: tuple[np.ndarray, np.ndarray],
                 markers: np.ndarray | None = None, cmap: str = "viridis"):
        configure_env()
        import pyvista as pv

        pv.OFF_SCREEN = True
        self.pv = pv
        self.dim = dim
        self.dx = dx
        self.width, self.height = round16(size[0]), round16(size[1])
        self.walls = walls
        self.title = title
        self.clim = clim
        self.categorical = categorical
        self.cmap = cmap
        self.plotter = pv.Plotter(off_screen=True, window_size=(self.width, self.height))
        self.plotter.set_background("white")
        self._bar_clim = None
        self._place_camera(camera, bounds)
        if markers is not None and len(markers):
            self._draw_markers(markers)

    # -- camera -----------------------------------------------------------------------------------
    def _place_camera(self, camera: str, bounds) -> None:
        lo, hi = (embed(np.asarray(b, dtype=float).reshape(1, -1))[0] for b in bounds)
        if self.dim == 2:
            lo[1], hi[1] = -0.5 * self.dx, 0.5 * self.dx
        direction, up = (np.asarray(v, dtype=float) for v in CAMERAS[camera])
        direction /= np.linalg.norm(direction)
        right = np.cross(direction, up)
        right /= np.linalg.norm(right)
        up = np.cross(right, direction)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        centre = 0.5 * (lo + hi)
        ext_r = np.ptp(corners @ right)
        ext_u = np.ptp(corners @ up)
        usable = 1.0 - BAR_FRACTION
        aspect = self.width / self.height
        scale = 0.5 * max(ext_u, ext_r / (aspect * usable)) * 1.06  # half-height of the view (m)
        half_width = scale * aspect
        # shift the view right so that the domain sits left of the colour bar
        focal = centre + right * (half_width * BAR_FRACTION)
        distance = 4.0 * float(np.linalg.norm(hi - lo)) + 1.0
        cam = self.plotter.camera
        cam.focal_point = tuple(focal)
        cam.position = tuple(focal - direction * distance)
        cam.up = tuple(up)
        cam.enable_parallel_projection()
        cam.parallel_scale = scale
        cam.clipping_range = (1e-3 * distance, 2.0 * distance + 10.0 * float(np.linalg.norm(hi - lo)))
        self.pixels_per_metre = self.height / (2.0 * scale)

    def point_size(self) -> float:
        return max(1.0, self.dx * self.pixels_per_metre)

    # -- static parts -------------------------------------------------------------------------------
    def _draw_markers(self, markers: np.ndarray) -> None:
        """Soil markers as a translucent region: the outer surface of the cells (one per marker, of the
        markers' own spacing, centred on them) that hold a marker, one-cell holes closed."""
        from scipy import ndimage
        from scipy.spatial import cKDTree

        pv = self.pv
        pts = embed(markers)
        if len(pts) > 1:
            d, _ = cKDTree(pts).query(pts, k=2)
            h = float(np.median(d[:, 1]))
        else:
            h = self.dx
        h = h if h > 0 else self.dx
        lo = pts.min(axis=0) - 1.5 * h  # one empty cell of margin, so that closing keeps the outline
        dims = np.floor((pts.max(axis=0) + 1.5 * h - lo) / h).astype(int) + 1
        if self.dim == 2:
            lo[1] = -0.5 * h
            dims[1] = 1
        idx = np.minimum(np.floor((pts - lo) / h).astype(int), dims - 1)
        occupied = np.zeros(tuple(dims), dtype=bool)
        occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        structure = ndimage.generate_binary_structure(3, 1)
        if self.dim == 2:
            structure[:, [0, 2], :] = False  # close in the x-z plane only
        occupied |= ndimage.binary_closing(occupied, structure=structure)
        grid = pv.ImageData(dimensions=tuple(int(n) + 1 for n in dims), spacing=(h, h, h), origin=tuple(lo))
        grid.cell_data["soil"] = occupied.ravel(order="F").astype(np.uint8)
        from vtkmodules.vtkFiltersGeometry import vtkGeometryFilter

        outer = vtkGeometryFilter()  # outer faces only: the cells' shared faces are left out
        outer.SetInputData(grid.threshold(0.5, scalars="soil"))
        outer.Update()
        region = pv.wrap(outer.GetOutput())
        self.plotter.add_mesh(region, color="#a0522d", opacity=0.25, name="markers", show_scalar_bar=False)

    # -- one frame ----------------------------------------------------------------------------------
    def draw(self, pos: np.ndarray, kind: np.ndarray, values: np.ndarray, time: float,
             keep: np.ndarray | None = None) -> np.ndarray:
        """Draw one frame; returns the picture (height, width, 3) uint8.

        keep: mask of particles to draw (active, within the slice); walls follow `walls`.
        """
        pv = self.pv
        keep = np.ones(len(kind), dtype=bool) if keep is None else keep
        wall = kind == WALL
        coloured = keep & ~wall  # walls are drawn grey (their colour in the kind map too)
        ps = self.point_size()
        pts = embed(pos)

        clim = self.clim
        vals = np.asarray(values, dtype=float)[coloured]
        if clim is None:
            clim = auto_range(vals)
        if self.categorical:
            clim = (-0.5, len(KIND_COLOURS) - 0.5)
        cloud = pv.PolyData(pts[coloured]) if coloured.any() else pv.PolyData(np.zeros((1, 3)))
        cloud.point_data["value"] = vals if coloured.any() else np.full(1, np.nan)
        kwargs = {"scalars": "value", "clim": clim, "render_points_as_spheres": True, "point_size": ps,
                  "name": "particles", "show_scalar_bar": False, "nan_opacity": 0.0}
        if self.categorical:
            from matplotlib.colors import ListedColormap

            kwargs["cmap"] = ListedColormap(KIND_COLOURS)
            kwargs["n_colors"] = len(KIND_COLOURS)
        else:
            kwargs["cmap"] = self.cmap
        actor = self.plotter.add_mesh(cloud, **kwargs)
        if self._bar_clim != tuple(clim):
            if self._bar_clim is not None:
                self.plotter.remove_scalar_bar()
            bar = {"title": self.title + "\n", "mapper": actor.mapper, "vertical": True, "position_x": 0.82,
                   "position_y": 0.08, "width": 0.05, "height": 0.76, "color": "black", "title_font_size": 16,
                   "label_font_size": 14, "fmt": "%.3g"}
            if self.categorical:
                bar.update(n_labels=0)
            self.plotter.add_scalar_bar(**bar)
            if self.categorical:
                self._label_kinds(actor)
            self._bar_clim = tuple(clim)

        wall_keep = keep & wall
        if self.walls != "hide" and wall_keep.any():
            opacity = 0.15 if self.walls == "translucent" else 1.0
            self.plotter.add_mesh(pv.PolyData(pts[wall_keep]), color="#9e9e9e", opacity=opacity,
                                  render_points_as_spheres=True, point_size=ps, name="walls")
        else:
            self.plotter.remove_actor("walls")
        self.plotter.add_text(f"t = {time:.4g} s", position=(10, self.height - 30), font_size=12, color="black",
                              name="time")
        return self.plotter.screenshot(return_img=True)

    def _label_kinds(self, actor) -> None:
        from ..kinds import KIND_NAMES

        lut = actor.mapper.lookup_table
        lut.annotations = {float(k): v for k, v in KIND_NAMES.items()}

    def close(self) -> None:
        self.plotter.close()


def auto_range(values: np.ndarray) -> tuple[float, float]:
    """Automatic colour range: the 0.5 % and 99.5 % quantiles of the finite values, so that a few
    outlying particles do not wash out the map; widened when all values are equal."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (0.0, 1.0)
    lo, hi = (float(x) for x in np.quantile(v, [0.005, 0.995]))
    if not hi > lo:
        pad = max(abs(lo) * 1e-3, 1e-12)
        lo, hi = lo - pad, hi + pad
    return (lo, hi)


def write_movie(path, images, fps: float) -> None:
    """Write pictures (all the same size) as an MP4 (H.264, yuv420p) or a GIF, by the file suffix."""
    import imageio.v2 as imageio

    path = str(path)
    if path.lower().endswith(".gif"):
        with imageio.get_writer(path, mode="I", duration=1000.0 / fps, loop=0) as w:
            for img in images:
                w.append_data(img)
        return
    with imageio.get_writer(path, fps=fps, codec="libx264", quality=8, pixelformat="yuv420p",
                            macro_block_size=16, ffmpeg_log_level="error") as w:
        for img in images:
            w.append_data(img)
