"""Pictures and movies of a run, drawn offscreen with PyVista (no display, no GUI).

- `frames`: what is drawn: particle frames from a run file or from snapshots taken during a run,
  and the scalar fields they can be coloured by (with units);
- `offscreen`: whether offscreen rendering works here, checked in a subprocess (a missing OpenGL
  library crashes VTK instead of raising);
- `draw`: the PyVista scene (particles, walls, soil markers, colour bar, camera presets) and movies;
- `command`: `taichi-sph render RUN.h5 ...`;
- `during_run`: pictures while a run goes (`output.images`), drawn by a separate process.

Importing this package does not import PyVista or VTK.
"""
