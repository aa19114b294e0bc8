"""Every body of water has a reference pressure (mode isph): a cluster of water particles joined to no
other water, which the free-surface tests read as interior, still gets a Dirichlet row.

Reference: a drop in the air is at the air's pressure (zero gauge) up to rho g times its own height, and
in free fall not even that. Without a Dirichlet row its PPE block has no reference pressure and its
source drives its pressure to arbitrary values (in a porous dam break at dx 5 mm: -280 MPa on four
particles, which then flew apart at 70 m/s and stopped the run).
"""

import numpy as np

G, RHO, DX = 9.81, 1000.0, 0.01


def _solver(monkeypatch_interior: bool, side: int = 2, drop_y: float = 0.20, above: float = 0.15):
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    cfg = load_config(data={
        "mode": "isph", "dim": 2, "dx": DX, "end_time": 0.01, "dt": 0.001,
        "tank": {"size": [0.3, 0.3], "boundary": "slip"},
        # porous ground in the pool's right-hand end: the rule runs only in scenes with soil
        "soil": {"regions": [{"min": [0.22, 0.0], "max": [0.3, 0.05], "eps0": 0.5, "d50": 0.01}]},
        "water": [{"min": [0.0, 0.0], "max": [0.3, 0.05]},
                  # a drop of side x side particles above the pool
                  {"min": [0.10, drop_y], "max": [0.10 + side * DX, drop_y + side * DX]}]})
    solver = ISPHSolver(cfg, build_scene(cfg))
    solver.initial_diagnostics()
    if monkeypatch_interior:
        # a surface test that reads the drop as interior (the case of the cone test in the pores)
        density = solver._k_density

        def drop_reads_interior():
            density()
            x = solver.x.to_numpy()
            free = solver.free.to_numpy()
            free[(x[:, 1] > above) & (solver.kind.to_numpy() == 0)] = 0
            solver.free.from_numpy(free)

        solver._k_density = drop_reads_interior
    return solver


def test_drop_read_as_interior_is_free_surface(ti_cpu):
    """A 2 x 2 drop 15 cm above a pool, its particles flagged interior: fewer particles than N_surf, so
    all of it is made free surface and its pressure is the Dirichlet value rho g dx / 2 = 49 Pa (the
    model's surface value; the air is at 0), bound rho g dx. Without the rule the PPE does not converge
    (relative residual 32 after 2000 iterations: the run stops)."""
    solver = _solver(True)
    solver.step(0.001)
    assert int(solver.closed_bodies[None]) == 1
    x, p = solver.x.to_numpy(), solver.p.to_numpy()
    water = solver.kind.to_numpy() == 0
    drop = water & (x[:, 1] > 0.15)
    assert drop.sum() == 4 and np.all(np.abs(p[drop]) <= RHO * G * DX), p[drop]
    assert np.all(solver.free.to_numpy()[drop] == 1)


def test_larger_body_read_as_interior_gets_one_dirichlet_row(ti_cpu):
    """A 5 x 5 body (25 particles, above N_surf = 17) flagged interior: one particle, one with the fewest
    neighbours (a corner), is made free surface, and the PPE converges (the step would stop otherwise)."""
    solver = _solver(True, side=5)
    solver.step(0.001)
    assert int(solver.closed_bodies[None]) == 1
    x = solver.x.to_numpy()
    drop = (solver.kind.to_numpy() == 0) & (x[:, 1] > 0.15)
    assert drop.sum() == 25 and solver.free.to_numpy()[drop].sum() == 1


def test_no_body_closed_when_every_body_has_a_surface(ti_cpu):
    """With the surface tests as they are the drop is free surface by eq 34's count: nothing to close."""
    solver = _solver(False)
    solver.step(0.001)
    assert int(solver.closed_bodies[None]) == 0


def test_a_drop_joined_only_at_the_support_edge_is_a_body_of_its_own(ti_cpu):
    """A 2 x 2 drop whose lowest particles are 0.95 r_e above the pool's top row (its PPE coefficient to the
    pool 0.5 % of a pair's at r = h), flagged interior: it counts as a body of its own and is made free
    surface, as a drop in the air is. Joined at 0.85 r_e (5 % of a pair at h) it belongs to the pool, whose
    surface gives it its reference pressure. Before BODY_LINK every pair within r_e joined bodies, and such
    weakly joined clusters of pore water were solved to 1e6-3e8 Pa in the porous dam break at dx 5 mm."""
    from taichi_sph.sph import kernels

    re = kernels.SUPPORT_FACTOR * DX
    top = 0.045  # the pool's top row
    for gap, closed in ((0.95, 1), (0.85, 0)):
        solver = _solver(True, drop_y=top + gap * re - 0.5 * DX, above=top + 0.5 * DX)
        solver.step(0.001)
        x = solver.x.to_numpy()
        drop = (solver.kind.to_numpy() == 0) & (x[:, 1] > top + 0.5 * DX)
        assert drop.sum() == 4
        assert int(solver.closed_bodies[None]) == closed, gap
        assert np.all(solver.free.to_numpy()[drop] == closed), gap


def test_sparse_pore_lattice_is_not_split_into_bodies(ti_cpu):
    """Ground of eps 0.18 (2D; its pore lattice's neighbours at 2.22-2.5 dx, beyond BODY_LINK r_e = 2.16 dx)
    saturated under a pool: lattice neighbours join within LATTICE_LINK spacings (up to r_e), so the
    closed-body rule closes what it closed when every pair within r_e joined, the 2 pore particles with no
    water within r_e (measured: 2 with either rule). With the lattice rule off, every pore particle was a
    body of its own: 20 closed."""
    from taichi_sph.config import load_config
    from taichi_sph.isph.solver import ISPHSolver
    from taichi_sph.scene import build_scene

    cfg = load_config(data={
        "mode": "isph", "dim": 2, "dx": DX, "end_time": 0.01, "dt": 0.001,
        "tank": {"size": [0.2, 0.2], "boundary": "slip"},
        "soil": {"regions": [{"min": [0.0, 0.0], "max": [0.2, 0.1], "eps0": 0.18, "d50": 0.01}]},
        "water": [{"min": [0.0, 0.0], "max": [0.2, 0.1], "porosity": 0.18},
                  {"min": [0.0, 0.1], "max": [0.2, 0.15]}]})
    solver = ISPHSolver(cfg, build_scene(cfg))
    solver.initial_diagnostics()
    solver.step(0.001)
    assert int(solver.closed_bodies[None]) <= 2
