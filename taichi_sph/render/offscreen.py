"""Can this machine render offscreen? VTK without a usable OpenGL (EGL or OSMesa) library crashes the
process (segmentation fault) instead of raising, so drawing happens in a child process that first
makes a tiny test picture (`probe_render`); `check_offscreen` asks the same question up front.

With no display (no DISPLAY / WAYLAND_DISPLAY), VTK is told to use its EGL window, which runs on
Mesa's software renderer when there is no GPU (Debian/Ubuntu packages libegl1, libegl-mesa0,
libgl1-mesa-dri).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

PACKAGES_HINT = "Debian/Ubuntu: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri"

_PROBE = "from taichi_sph.render.offscreen import probe_render; probe_render(); print('ok')"


def probe_render() -> None:
    """Draw a 32 x 32 picture of one point; raises (or, without OpenGL, crashes) when it cannot."""
    configure_env()
    import numpy as np
    import pyvista as pv

    p = pv.Plotter(off_screen=True, window_size=(32, 32))
    p.add_points(np.zeros((1, 3)))
    img = p.screenshot(return_img=True)
    p.close()
    if img is None or img.shape[:2] != (32, 32):
        raise RuntimeError(f"offscreen picture has the wrong shape {getattr(img, 'shape', None)}")


def crash_message(returncode: int) -> str:
    return (f"offscreen rendering is not available on this machine: the renderer crashed (signal {-returncode}); "
            f"an OpenGL library (EGL or OSMesa) is missing ({PACKAGES_HINT})")


def configure_env(env: dict | None = None) -> dict:
    """Environment for offscreen VTK: the EGL window when there is no display."""
    env = os.environ if env is None else env
    if not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY"):
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    env.setdefault("PYVISTA_OFF_SCREEN", "true")
    return env


def missing_modules(movie: str | None = None) -> list[str]:
    """Python modules rendering needs that are not installed (imageio-ffmpeg only for MP4)."""
    need = ["pyvista"]
    if movie:
        need.append("imageio")
        if not movie.lower().endswith(".gif"):
            need.append("imageio_ffmpeg")
    return [m for m in need if importlib.util.find_spec(m) is None]


def check_offscreen(timeout: float = 120.0) -> str | None:
    """None when a tiny offscreen picture can be made here; otherwise one line saying why not."""
    env = configure_env(dict(os.environ))
    try:
        res = subprocess.run([sys.executable, "-c", _PROBE], check=False, env=env, capture_output=True, text=True,
                             timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"offscreen rendering test did not finish in {timeout:.0f} s"
    if res.returncode == 0 and "ok" in res.stdout:
        return None
    if res.returncode < 0:
        return crash_message(res.returncode)
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    why = lines[-1].strip() if lines else f"exit code {res.returncode}"
    return f"offscreen rendering is not available on this machine: {why} ({PACKAGES_HINT})"
