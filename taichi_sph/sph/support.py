"""The kernel's support radius in units of the particle spacing (SPEC 3; seed 000: r_e = 2.4 dx), for
the kernels (sph/kernels.py) and for the config checks and the scene, which must not import Taichi."""

#: support radius r_e / dx of the cubic B-spline (smoothing length h = r_e / 2)
SUPPORT_FACTOR = 2.4
