"""Equations of state of mode wcsph_biot (seed 002 section 2.4 (1)), as ti.funcs with numpy twins.

Pressures are gauge pressures, relative to the ambient (absolute) pressure p0 above the free surface:
the momentum equation (eq 34) sees only differences, and a uniform p0 acting on a truncated kernel
support at a free surface would otherwise push surface particles out. Both laws take one form,

    p - p0 = B ((rho / rho0)^gamma - 1),     c^2 = dp/drho = gamma B / rho0 (rho / rho0)^(gamma - 1):

- water, Tait eq 41: gamma = 7 and B = rho0 c0^2 / gamma, with the sound speed c0 at least ten times
  the largest expected flow speed so that the density varies by less than 1 % (the seed's p0 in front
  of the bracket of eq 41 is this modulus B);
- air, eq 39-40: p - p0 = B (rho - rho0) / rho0 with the modulus B = gamma_gas p of eq 40, which
  depends on the pressure itself. Integrating dp = B drho / rho = gamma_gas p drho / rho gives the
  adiabatic law p = p0 (rho / rho0)^gamma_gas, i.e. the form above with B = p0, gamma = 1.403; to first
  order in (rho - rho0) / rho0 it is eq 39. rho0 is the air density at p0 (seed: 1.207 kg/m^3), so
  c0 = sqrt(gamma_gas p0 / rho0) = 341 m/s at 100 kPa.
"""

import numpy as np
import taichi as ti


@ti.func
def pressure(rho, rho0, b, gamma):
    """Gauge pressure p - p0 = B ((rho / rho0)^gamma - 1) (eq 41 for water, eq 39-40 for air)."""
    return b * ((rho / rho0) ** gamma - 1.0)


@ti.func
def sound_speed(rho, rho0, b, gamma):
    """Local sound speed c = sqrt(dp/drho) = sqrt(gamma B / rho0) (rho / rho0)^((gamma - 1) / 2)."""
    return ti.sqrt(gamma * b / rho0 * (rho / rho0) ** (gamma - 1))


def pressure_np(rho, rho0: float, b: float, gamma: float):
    """Numpy twin of `pressure`."""
    return b * ((np.asarray(rho, float) / rho0) ** gamma - 1.0)


def density_np(p, rho0: float, b: float, gamma: float):
    """Inverse of `pressure`: the density at gauge pressure p, rho0 (1 + p / B)^(1 / gamma)."""
    return rho0 * (1.0 + np.asarray(p, float) / b) ** (1.0 / gamma)


def sound_speed_np(rho, rho0: float, b: float, gamma: float):
    """Numpy twin of `sound_speed`."""
    return np.sqrt(gamma * b / rho0 * (np.asarray(rho, float) / rho0) ** (gamma - 1.0))


def tait_modulus(rho0: float, c0: float, gamma: float) -> float:
    """B = rho0 c0^2 / gamma of the Tait equation eq 41, so that c = c0 at rho = rho0."""
    return rho0 * c0 * c0 / gamma
