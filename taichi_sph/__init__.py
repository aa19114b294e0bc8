"""taichi-sph: stabilized ISPH and WCSPH-Biot particle simulation on Taichi."""

__version__ = "0.1.0"
