"""Obstacles with a prescribed motion (`obstacles[k].motion`), shared by both solver modes: each moving
obstacle is a rigid body of wall particles translated at its configured velocity between its start
and stop times. A wall particle's velocity field holds that velocity (zero for fixed walls), and the
wall conditions of both modes take the fluid velocity relative to it:

- mode isph, virtual marker (seed 000): a wall seen from fluid particle i moves with
  v_w + M (v_i - v_w), M = -1 (no-slip) or the reflection of the normal component (slip), in the
  viscous term; the PPE's divergence takes only the reflected normal component (impermeability);
- mode wcsph_biot, Morris/Takeda (seed 002 eq 50-51): the relative velocity v_i - v_B of a boundary
  particle is beta (v_i - v_w) (no-slip), or its normal component (slip).

A motion is a constant velocity, or an oscillation x(t) = A sin(2 pi (t - start) / T) (a paddle,
Stokes' second problem), between its start and stop times. The wall pressure keeps its hydrostatic
Neumann form: the wall's acceleration (the rho a_w . n term of the Neumann condition) is left out,
which is exact for a constant velocity and for a wall oscillating along its own face.
"""

import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..backend import on_cpu
from . import operators


@dataclass(frozen=True)
class Motion:
    """A rigid translation: constant `velocity` (m/s), or the oscillation A sin(2 pi tau / period) with
    displacement amplitude `amplitude` (m), tau the time since `start`, both between `start` and `stop`
    (s; inf: to the end)."""

    start: float
    stop: float
    velocity: np.ndarray | None = None
    amplitude: np.ndarray | None = None
    period: float = 0.0
    #: seconds over which a constant velocity ramps up after start and down before stop (half cosine)
    ramp: float = 0.0

    @classmethod
    def from_config(cls, m) -> "Motion":
        stop = math.inf if m.stop is None else float(m.stop)
        if m.amplitude is not None:
            return cls(float(m.start), stop, amplitude=np.asarray(m.amplitude, float), period=float(m.period))
        return cls(float(m.start), stop, velocity=np.asarray(m.velocity, float), ramp=float(getattr(m, "ramp", 0.0)))

    def _ramped(self, tau: float) -> float:
        """Distance covered at unit speed tau seconds after start, the speed (1 - cos(pi u / T)) / 2 over
        the first T = ramp seconds and mirrored over the last T before stop."""
        T = self.ramp
        if T <= 0.0:
            return tau

        def up(u: float) -> float:
            return u / 2.0 - T / (2.0 * math.pi) * math.sin(math.pi * u / T) if u < T else u - T / 2.0

        span = self.stop - self.start
        if tau <= span - T:
            return up(tau)
        return up(span - T) + up(T) - up(span - tau)

    def displacement(self, t: float) -> np.ndarray:
        """Displacement at time t from the configured place."""
        tau = max(0.0, min(t, self.stop) - self.start)
        if self.amplitude is not None:
            return self.amplitude * math.sin(2.0 * math.pi * tau / self.period)
        return self.velocity * self._ramped(tau)

    def step_velocity(self, t0: float, t1: float) -> np.ndarray:
        """Mean velocity over the step [t0, t1] (displacement over the step / its length), so that the
        body is moved by exactly its displacement."""
        return (self.displacement(t1) - self.displacement(t0)) / (t1 - t0)

    def reach(self, end_time: float) -> tuple[np.ndarray, np.ndarray]:
        """Smallest and largest displacement per axis up to end_time (to size the neighbour grid)."""
        if self.amplitude is not None:
            return -np.abs(self.amplitude), np.abs(self.amplitude)
        d = self.displacement(end_time)
        return np.minimum(d, 0.0), np.maximum(d, 0.0)


@ti.data_oriented
class WallMotion:
    """Per-particle body index (-1: not moving) and configured place (`origin`), and per body its
    velocity over the current step and its displacement at the step's end. Positions are set from the
    origin and the exact displacement, never summed step by step, so a body is where its motion says
    to rounding. The solver lists `body` and `origin` among its particle fields (reordered with them)
    and its checkpoint fields."""

    def __init__(self, scene, dim: int, period):
        self.motions = list(scene.motions)
        self.dim = dim
        # the bodies' motion reaches the device through host arrays on the CPU (one launch for all
        # bodies), by value on GPUs (`set_step`)
        self._host_arrays = on_cpu()
        self.period = period
        self.periodic = any(v > 0.0 for v in period)
        n = scene.n
        self.body = ti.field(ti.i32, n)
        self.body.from_numpy(scene.body if scene.body is not None else np.full(n, -1, np.int32))
        # the place in f64 at either precision, as mode wcsph_biot keeps positions: an f32 place differs
        # from the motion by up to 6e-8 of the coordinate, which the guard's 1e-6 dx reads as a moved wall
        self.origin = ti.Vector.field(dim, ti.f64, n if self.motions else 1)
        if self.motions:
            self.origin.from_numpy(scene.position.astype(np.float64))
        nb = max(len(self.motions), 1)
        self.vel = ti.Vector.field(dim, float, nb)
        self.disp = ti.Vector.field(dim, ti.f64, nb)

    @property
    def any(self) -> bool:
        return bool(self.motions)

    def fields(self) -> list:
        """Per-particle fields to reorder with the solver's (none when nothing moves)."""
        return [self.body, self.origin] if self.motions else []

    def set_step(self, t0: float, t1: float) -> None:
        """Velocity of every body over the step [t0, t1] and its displacement at t1."""
        if not self.motions:
            return
        if self._host_arrays:
            self._k_set(np.stack([m.step_velocity(t0, t1) for m in self.motions]).astype(np.float64),
                        np.stack([m.displacement(t1) for m in self.motions]).astype(np.float64))
            return
        for b, m in enumerate(self.motions):  # GPUs: by value, one launch per body (most scenes have one)
            vel, disp = np.zeros(3), np.zeros(3)
            vel[: self.dim] = m.step_velocity(t0, t1)
            disp[: self.dim] = m.displacement(t1)
            self._k_set_one(b, vel, disp)

    @ti.kernel
    def _k_set(self, vel: ti.types.ndarray(), disp: ti.types.ndarray()):
        """Both per-body arrays in one launch (two from_numpy calls cost two; a step of a small scene
        lasts ~1-2 ms, of which they took ~0.1-0.2 ms)."""
        ti.loop_config(serialize=True)
        for b in range(vel.shape[0]):
            for d in ti.static(range(self.dim)):
                self.vel[b][d] = ti.cast(vel[b, d], float)
                self.disp[b][d] = disp[b, d]

    @ti.kernel
    def _k_set_one(self, b: ti.i32, vel: ti.types.vector(3, ti.f64), disp: ti.types.vector(3, ti.f64)):
        """Body b's velocity and displacement passed by value (GPUs: a host array argument costs Taichi a
        device buffer allocated, copied and freed at every launch there)."""
        for d in ti.static(range(self.dim)):
            self.vel[b][d] = ti.cast(vel[d], float)
            self.disp[b][d] = disp[d]

    @ti.func
    def position(self, i):
        """Place of moving-body particle i at the end of the step (f64)."""
        xn = self.origin[i] + self.disp[self.body[i]]
        if ti.static(self.periodic):
            xn = operators.wrap(xn, self.period)
        return xn

    @ti.kernel
    def assign(self, v: ti.template(), n: ti.i32):
        """v = v_body for the particles of moving bodies (fixed walls keep v = 0): the wall velocity the
        fluid sees during the step."""
        for i in range(n):
            b = self.body[i]
            if b >= 0:
                v[i] = self.vel[b]

    @ti.kernel
    def advance(self, x: ti.template(), n: ti.i32):
        """Moving-body particles to their place at the end of the step."""
        for i in range(n):
            if self.body[i] >= 0:
                x[i] = ti.cast(self.position(i), x.dtype)
