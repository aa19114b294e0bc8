"""taichi_sph.taichi_frontend: the fast source-position string is Taichi's own, node for node, and the
memoized source reading gives Taichi's own trees, function for function."""

import json
import subprocess
import sys

from .conftest import ROOT, cli_env

SCRIPT = r"""
import ast
import json
import taichi as ti
from taichi_sph import taichi_frontend
from taichi_sph.backend import taichi_options
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

original = taichi_frontend.original_get_pos_info()
assert taichi_frontend.install() and taichi_frontend.install()  # a second call keeps the first
fast = ASTTransformerContext.get_pos_info
assert fast is not original and fast.taichi_original is original
counts = {"nodes": 0, "fast": 0, "differ": 0}


def checked(self, node):
    a, b = original(self, node), fast(self, node)
    counts["nodes"] += 1
    counts["fast"] += node.lineno == node.end_lineno and len(self.src[node.lineno - 1]) <= 80
    if a != b:
        counts["differ"] += 1
        counts.setdefault("first", (a, b))
    return a


ASTTransformerContext.get_pos_info = checked

# each function's tree and context: built with Taichi's own source reading and with the memoized one
from taichi.lang import kernel_impl

memoized = {n: getattr(kernel_impl, n) for n in ("getsourcefile", "getsourcelines", "textwrap")}
own = {"getsourcefile": memoized["getsourcefile"].taichi_original,
       "getsourcelines": memoized["getsourcelines"].taichi_original, "textwrap": memoized["textwrap"]._module}
tree_and_ctx = kernel_impl._get_tree_and_ctx
counts.update(trees=0, trees_differ=0)


def checked_tree(self, *args, **kwargs):
    for name, value in own.items():
        setattr(kernel_impl, name, value)
    tree0, ctx0 = tree_and_ctx(self, *args, **kwargs)
    for name, value in memoized.items():
        setattr(kernel_impl, name, value)
    tree, ctx = tree_and_ctx(self, *args, **kwargs)
    counts["trees"] += 1
    same = (ast.dump(tree0, include_attributes=True) == ast.dump(tree, include_attributes=True)
            and (ctx0.src, ctx0.file, ctx0.lineno_offset, ctx0.indent) == (ctx.src, ctx.file, ctx.lineno_offset,
                                                                             ctx.indent))
    if not same:
        counts["trees_differ"] += 1
        counts.setdefault("first_tree", self.func.__qualname__)
    return tree, ctx


kernel_impl._get_tree_and_ctx = checked_tree
ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=1, log_level=ti.WARN, **taichi_options())
from taichi_sph.config import load_config
from taichi_sph.scene import build_scene
from taichi_sph.solvers import make_solver

# the porous free fall (isph: porosity, eq 34 and its ground rules, the ELL PPE) and the saturated soil
# column (wcsph_biot: soil, water, drag, plasticity): two steps each, every kernel of a step compiled
for config, variant in (("freefall", "coarse"), ("soil_column", None)):
    cfg = load_config(f"configs/{config}.yaml", [], variant)
    s = make_solver(cfg, build_scene(cfg))
    s.initial_diagnostics()
    for _ in range(2):
        s.step(float(cfg.dt if isinstance(cfg.dt, float) else 1e-4))
print(json.dumps(counts))
"""


def test_fast_source_positions_equal_taichis():
    """Every node that Taichi's front end asks a position for while it compiles a porous isph step and a
    wcsph_biot soil step: the installed method returns Taichi's string. Most nodes take the fast path
    (a single line within 80 columns), so the comparison covers it; the memo returns each string again
    for every inlining of the same function. Every function that the front end reads (each kernel and
    each inlining of a ti.func): the tree (with its line and column numbers) and the source lines, file
    and offsets of its context are those of Taichi's own reading of the source."""
    r = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=cli_env(), capture_output=True, text=True,
                       timeout=600, check=False)
    assert r.returncode == 0, r.stderr[-3000:]
    counts = json.loads(r.stdout.strip().splitlines()[-1])
    assert counts["differ"] == 0, counts.get("first")
    assert counts["nodes"] > 10000 and counts["fast"] > 0.5 * counts["nodes"], counts
    assert counts["trees_differ"] == 0, counts.get("first_tree")
    assert counts["trees"] > 500, counts
