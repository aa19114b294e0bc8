"""A no-slip wall beside water in free fall, with the Smagorinsky eddy viscosity on (mode isph).

Reference: Stokes' first problem. Water falling past a still wall is, in its own frame, water at rest
beside a wall that moves at g t; the wall's influence spreads by diffusion over sqrt(nu t) (0.3 mm after
0.1 s), and at the first particle's distance from the wall (dx / 2 = 5 mm) the velocity deficit is
below erfc(dx / (4 sqrt(nu t))) = erfc(7.9) ~ 1e-28 of g t. So every particle of the block, the column
against each wall included, falls at g t.

Before the wall pairs of the viscous term dropped the eddy viscosity (docs/isph.md, "No eddy viscosity in
the wall's shear"), the column against each wall fell at 0.47 of g t after 0.1 s (dx 1 cm, dt 1 ms): the
model's nu_T, taken from the shear against the mirrored wall velocity, was ~2e-3 m^2/s there, two
thousand times the water's. In the seed's free fall that column lagged the core by a factor 2-3 and held water
above the porous layer (docs/freefall.md).
"""

import numpy as np
import pytest

G = 9.81
DX = 0.01
WIDTH = 0.2


def _block(dt):
    from taichi_sph.config import load_config

    return load_config(data={
        "mode": "isph", "dim": 2, "dx": DX, "end_time": 0.1, "dt": dt,
        "fluid": {"turbulence": "smagorinsky"},
        "tank": {"size": [WIDTH, 0.6], "boundary": "no_slip"},
        "water": [{"min": [0.0, 0.40], "max": [WIDTH, 0.50]}]})


@pytest.mark.parametrize("dt", [0.001, 0.0005])
def test_no_slip_wall_does_not_hold_back_falling_water(ti_cpu, dt):
    """Measured (dx 1 cm, t = 0.1 s): the columns against the walls fall at 1 - 6.7e-4 / 1 - 7.0e-4 of g t
    at dt 1 / 0.5 ms, the core at 1 -+ 2e-5, the largest sideways speed 2.3e-4 / 2.6e-4 of g t. What is
    left is the water's own (laminar) viscosity across the half spacing to the wall, resolved on a
    centimetre grid: ~nu_w 4 v / dx^2, 1e-3 of g t integrated over 0.1 s. Bounds 1e-3 (wall columns),
    5e-5 (core), 4e-4 (sideways). With the eddy viscosity in the wall's shear the wall columns lagged by
    53 %, the core by 1.3 % and the water moved sideways at 4-6 % of g t (nu_T up to 2.1e-3 m^2/s)."""
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    cfg = _block(dt)
    scene = build_scene(cfg)
    solver = ISPHSolver(cfg, scene)
    solver.initial_diagnostics()
    steps = round(0.1 / dt)
    for _ in range(steps):
        solver.step(dt)
    x = solver.x.to_numpy()
    v = solver.v.to_numpy()
    kind = solver.kind.to_numpy()
    water = kind == 0
    x, v = x[water], v[water]
    assert len(x) == 200
    gt = G * steps * dt
    wall_column = (x[:, 0] < DX) | (x[:, 0] > WIDTH - DX)
    core = ~wall_column
    assert wall_column.sum() == 20
    lag_wall = 1.0 + v[wall_column, 1].mean() / gt
    lag_core = 1.0 + v[core, 1].mean() / gt
    assert abs(lag_core) < 5e-5, lag_core
    assert abs(lag_wall) < 1e-3, lag_wall
    # nothing pushes the water sideways: the walls' shear acts along them only
    assert np.abs(v[:, 0]).max() < 4e-4 * gt
