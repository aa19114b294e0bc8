"""Two-stage runs of mode wcsph_biot (seed 002 section 3.5): the soil of a run starts from the end of an
earlier run (`wcsph.soil.start_from`), typically a geostatic stage (gravity loading at rest, with
`wcsph.soil.damping`) whose end state then carries the flood or head rise of the next stage.

What carries over, per soil particle, from the chosen frame of the earlier run file: position,
effective stress, accumulated plastic shear strain and density (eq 48). The soil starts the new stage
at rest (the geostatic stage ends at rest; its leftover velocity is damping noise). Water, air and
walls come from the new config, so a stage may add a river or take the damping away; the water
starts hydrostatic as in any run. The soil particles of both runs are matched in id order: both
configs must build the same soil (same `soil_blocks` and dx); the match is checked on the starting
positions of the earlier run (within dx / 2) so that another geometry is an input error, not a
silent mix-up.

Numpy and h5py only (no Taichi): it runs before any kernel, and every failure is an InputError
naming the key or the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scene import SOIL

KEY = "wcsph.soil.start_from"


def load_stage(cfg, scene) -> dict | None:
    """Soil state at the start of this stage, or None without `start_from`: arrays over the scene's soil
    particles (id order) `position`, `stress` (k, dim, dim), `plastic_strain`, `density`."""
    src = cfg.wcsph.soil.start_from
    if src is None:
        return None
    from ..io.hdf5 import RunFile, RunFileError

    path = Path(src.run)
    if not path.is_file():
        raise InputError(f"config key '{KEY}.run': no run file '{path}'")
    try:
        with RunFile(path) as rf:
            if rf.mode != "wcsph_biot" or rf.dim != cfg.dim or abs(rf.dx - cfg.dx) > 1e-9 * cfg.dx:
                raise InputError(f"config key '{KEY}.run': '{path}' is a {rf.mode} run in {rf.dim}D at dx {rf.dx:g}; "
                                 f"this stage needs wcsph_biot in {cfg.dim}D at dx {cfg.dx:g}")
            status = rf.attrs.get("status", "")
            if status != "completed":
                raise InputError(f"config key '{KEY}.run': '{path}' did not complete (status {status or 'unknown'})")
            if rf.n_frames == 0 or not -rf.n_frames <= src.frame < rf.n_frames:
                raise InputError(f"config key '{KEY}.frame': {src.frame} is not a frame of '{path}' "
                                 f"({rf.n_frames} frames)")
            soil_old = rf.kind == SOIL
            start = rf.field("position", 0)[soil_old]
            frame = rf.frame(src.frame)
            if "effective_stress" not in frame:
                raise InputError(f"config key '{KEY}.run': '{path}' has no soil stress (no soil particles)")
            out = {"position": frame["position"][soil_old], "stress": frame["effective_stress"][soil_old],
                   "plastic_strain": frame["plastic_strain"][soil_old], "density": frame["density"][soil_old],
                   "time": float(frame["time"])}
    except (OSError, RunFileError) as exc:
        raise InputError(f"config key '{KEY}.run': '{path}' is not a readable run file ({exc})") from None
    soil_new = scene.kind == SOIL
    here = scene.position[soil_new]
    if len(here) != len(start) or (len(here) and np.abs(here - start).max() > 0.5 * cfg.dx):
        raise InputError(f"config key '{KEY}.run': the soil of '{path}' ({len(start)} particles) is not the soil "
                         f"this config builds ({len(here)} particles); give both stages the same soil_blocks and dx")
    return out


def apply_stage(stage: dict, scene, rho: np.ndarray, stress: np.ndarray) -> np.ndarray:
    """Put the earlier stage's soil into the start state (in place): positions into `scene.position`,
    densities into `rho` and stresses into `stress`; returns the plastic strain of every particle."""
    soil = scene.kind == SOIL
    scene.position[soil] = stage["position"]
    rho[soil] = stage["density"]
    stress[soil] = stage["stress"]
    eps_p = np.zeros(scene.n)
    eps_p[soil] = stage["plastic_strain"]
    return eps_p
