"""Proof that feature code a scene does not use costs it nothing (ti.static switches).

Mode isph compiles porous ground (soil markers, eq 32 porosity, drag of eq 9) and Smagorinsky
turbulence (eq 3) behind `ti.static(self.porous)` and `ti.static(self.turbulence)`, and skips
their Python-side calls with plain `if`. This tool builds a second solver class with that code
*absent*: it parses taichi_sph/isph/solver.py and the modules of its mixins (surface.py,
shifting.py, ground_density.py), replaces every `if` whose condition names `self.porous` or
`self.turbulence` by its `else` branch (the code a scene without them would run), writes the results to
temporary modules (the stripped solver importing the stripped mixins) and imports them beside the
originals. Then it runs the same
free-water scene (the 2D dam break of configs/dambreak.yaml, fixed dt) with both classes in one
process, interleaving chunks of steps so that load from other processes hits both alike, and
reports the best and median chunk time of each. It also checks that both give bitwise the same
particle positions, which shows the stripped build computes the same thing.

    python tools/bench_static.py [--steps 20] [--chunks 10] [--set dx=0.0025]
"""

import argparse
import ast
import importlib.util
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

FEATURES = ("porous", "turbulence")


def _names_feature(test: ast.expr) -> bool:
    for node in ast.walk(test):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self"
                and node.attr in FEATURES):
            return True
    return False


class _Strip(ast.NodeTransformer):
    """Replace `if <condition naming a feature flag>: A else: B` by B."""

    def __init__(self):
        self.removed = 0

    def visit_If(self, node):
        self.generic_visit(node)
        if _names_feature(node.test):
            self.removed += 1
            return node.orelse or None
        return node

    def generic_visit(self, node):
        super().generic_visit(node)
        for field in ("body", "orelse"):  # a block emptied by the strip needs a statement
            block = getattr(node, field, None)
            if isinstance(block, list) and not block and field == "body":
                block.append(ast.Pass())
        return node


#: the modules of taichi_sph/isph/ that hold ISPHSolver's code: its mixins first, the solver last
SOLVER_MODULES = ("surface", "shifting", "ground_density", "solver")


def stripped_solver_class(tmpdir: Path):
    """ISPHSolver with the feature code removed from it and its mixins, as modules in the taichi_sph.isph
    package (`<module>_without_features`, the stripped solver importing the stripped mixins)."""
    strip = _Strip()
    mod = None
    for stem in SOLVER_MODULES:
        tree = ast.parse((ROOT / "taichi_sph" / "isph" / f"{stem}.py").read_text())
        tree = strip.visit(tree)
        for node in ast.walk(tree):  # from .surface import SurfaceTests -> from .surface_without_features ...
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module in SOLVER_MODULES:
                node.module = f"{node.module}_without_features"
        tree = ast.fix_missing_locations(tree)
        path = tmpdir / f"{stem}_without_features.py"
        path.write_text(ast.unparse(tree))
        name = f"taichi_sph.isph.{stem}_without_features"
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return mod.ISPHSolver, strip.removed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20, help="steps per chunk")
    ap.add_argument("--chunks", type=int, default=10)
    ap.add_argument("--threads", type=int, default=None, help="CPU threads (default: all cores); with 1 the "
                    "run is deterministic and both builds must agree bitwise")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    from bench import machine

    from taichi_sph import backend
    from taichi_sph.config import load_config
    from taichi_sph.scene import build_scene
    from taichi_sph.solvers import make_solver

    be = backend.init("cpu", "auto", threads=args.threads)
    cfg = load_config(ROOT / "configs" / "dambreak.yaml", ["dt=0.0005", *args.overrides])
    assert not cfg.soil.regions and cfg.fluid.turbulence == "none"
    with tempfile.TemporaryDirectory() as tmp:
        Stripped, removed = stripped_solver_class(Path(tmp))
        solvers = {"features present": make_solver(cfg, build_scene(cfg)),
                   "features absent": Stripped(cfg, build_scene(cfg))}
        for s in solvers.values():
            s.initial_diagnostics()
            for _ in range(3):  # JIT compilation out of the timing
                s.step(cfg.dt)
        times = {k: [] for k in solvers}
        for _ in range(args.chunks):
            for k, s in solvers.items():
                t0 = time.perf_counter()
                for _ in range(args.steps):
                    s.step(cfg.dt)
                times[k].append((time.perf_counter() - t0) / args.steps)
        xs = [s.fields_by_id()["position"] for s in solvers.values()]
    same = bool(np.array_equal(xs[0], xs[1]))
    diff = float(np.max(np.abs(xs[0] - xs[1])))
    n = solvers["features present"].n_water
    print(f"Machine: {machine()}, {args.threads or os.cpu_count()} threads, {be['precision']}, load average "
          f"{os.getloadavg()[0]:.1f}; {n} water particles, {args.chunks} chunks of {args.steps} steps "
          f"interleaved; {removed} feature branches removed in the stripped build; positions after "
          f"{solvers['features present'].step_count} steps bitwise equal: {same} (largest difference {diff:.1e} m; "
          "with more than one thread, atomic sums add in varying order).")
    print()
    print("| build | best chunk ms/step | median chunk ms/step |")
    print("|---|---:|---:|")
    for k, t in times.items():
        print(f"| {k} | {1e3 * min(t):.2f} | {1e3 * statistics.median(t):.2f} |")
    a, b = (min(t) for t in times.values())
    ma, mb = (statistics.median(t) for t in times.values())
    print(f"\npresent / absent: best {a / b:.3f}, median {ma / mb:.3f}")
    return 0 if same or (args.threads or os.cpu_count()) > 1 else 1


if __name__ == "__main__":
    sys.exit(main())
