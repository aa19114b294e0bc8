"""Particle kinds: the codes of /particles/kind in a run file and of every solver's `kind` field, and
their names. Imports nothing, so that any layer (io/ without Taichi, the config checks, the solvers)
can use it."""

WATER, WALL, SOIL, AIR = 0, 1, 2, 3
#: kind code -> name
KIND_NAMES: dict[int, str] = {WATER: "water", WALL: "wall", SOIL: "soil", AIR: "air"}
