"""A faster source-position string for Taichi's kernel compiler (its Python front end), same text.

Taichi 1.7 builds, for every statement and expression of a kernel it compiles, the source position that
its error messages quote: the line and a row of carets under the node, both passed through a
`textwrap.TextWrapper` of width 80 (`ASTTransformerContext.get_pos_info`). It does so on every
compilation, also when the compiled kernel then comes from the offline cache, and the wrapping is half
of the front end's time: 3.7 of 7.4 s for the 159 kernels of the 3D free fall's two PPE solvers, about
0.7 s of a short 2D run's 2.8 s. A kernel is compiled once per scene, so each run and each test pays it.

`install()` replaces that method with one that gives the same string: a node on one line whose source
line and carets fit in 80 columns (no whitespace but blanks) is what the wrapper would return, the line
and the carets with their trailing blanks dropped; every other node (one over several lines, a longer
line) goes to Taichi's own method. The text feeds error messages and debug information only: the
compiled kernels and the offline cache's keys are those of Taichi's method (tests/test_taichi_frontend.py
compares the two on every node of a porous isph step's and a soil step's kernels).
"""

from __future__ import annotations

WIDTH = 80  # Taichi's TextWrapper width
_OTHER_WHITESPACE = "\t\n\r\x0b\x0c"  # the wrapper turns these into blanks: such a line takes Taichi's path


def _fast_get_pos_info(original):
    def get_pos_info(self, node):
        lineno = node.lineno
        if lineno == node.end_lineno:
            code = self.src[lineno - 1]
            if len(code) <= WIDTH and code.strip() and not any(c in code for c in _OTHER_WHITESPACE):
                col = self.indent + node.col_offset
                end = self.indent + node.end_col_offset
                if 0 <= col < end <= WIDTH:
                    return (f'File "{self.file}", line {lineno + self.lineno_offset}, in {self.func.func.__name__}:\n'
                            f"{code.rstrip(' ')}\n{' ' * col}{'^' * (end - col)}\n")
        return original(self, node)

    get_pos_info.taichi_original = original
    return get_pos_info


def install() -> bool:
    """Replace Taichi's `get_pos_info` by the fast one (once; harmless to call again). False where this
    Taichi has no such method (another version): its own is then kept."""
    try:
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    except ImportError:
        return False
    current = getattr(ASTTransformerContext, "get_pos_info", None)
    if current is None:
        return False
    if getattr(current, "taichi_original", None) is None:
        ASTTransformerContext.get_pos_info = _fast_get_pos_info(current)
    return True


def original_get_pos_info():
    """Taichi's own method (for the comparison test), installed or not."""
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    current = ASTTransformerContext.get_pos_info
    return getattr(current, "taichi_original", current)
