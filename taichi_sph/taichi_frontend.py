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

The front end also reads each function's source again every time a kernel inlines it: `inspect`'s
source file and lines (each call walks `sys.modules` in `inspect.getmodule`), then `textwrap.fill` over
every line and `textwrap.dedent` over the whole. All of these are pure in a process whose files do not
change, so `install()` memoizes them by the function's code object and by their arguments, and the
source-position strings by the node's place in its file; Taichi still parses and transforms every
function it inlines, so the trees, the kernels and the offline cache's keys are those it built before
(the test compares the trees and the strings).
"""

from __future__ import annotations

import functools

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
        ASTTransformerContext.get_pos_info = _memo_pos_info(_fast_get_pos_info(current))
    _memo_sources()
    return True


def _memo_pos_info(method):
    """`method` (a get_pos_info) memoized by the node's place: the string is a function of the file, the
    function's name and first line, the node's lines and columns, its kind and (a block) its body's first
    line, all fixed by where the node stands in a file that does not change (its first line's text is in
    the key too, for sources that share a file name, as `python -c` code does)."""
    memo = {}

    def get_pos_info(self, node):
        body = getattr(node, "body", None)
        key = (self.file, self.lineno_offset, self.indent, self.func.func.__name__, type(node).__name__,
               node.lineno, node.end_lineno, node.col_offset, node.end_col_offset,
               body[0].lineno if isinstance(body, list) and body else None, self.src[node.lineno - 1])
        text = memo.get(key)
        if text is None:
            text = memo[key] = method(self, node)
        return text

    get_pos_info.taichi_original = method.taichi_original
    return get_pos_info


class _MemoTextwrap:
    """The module `textwrap` with `fill` and `dedent` memoized (pure functions of their arguments)."""

    def __init__(self, module):
        self._module = module
        self.fill = functools.lru_cache(maxsize=None)(module.fill)
        self.dedent = functools.lru_cache(maxsize=None)(module.dedent)

    def __getattr__(self, name):
        return getattr(self._module, name)


def _memo_by_code(function):
    """`function(obj)` of Taichi's `_wrap_inspect` memoized by obj's code object (a list result copied)."""
    memo = {}

    @functools.wraps(function)
    def memoized(obj):
        key = getattr(obj, "__code__", obj)
        if key not in memo:
            memo[key] = function(obj)
        value = memo[key]
        return (list(value[0]), value[1]) if isinstance(value, tuple) else value

    memoized.taichi_original = function
    return memoized


def _memo_sources() -> None:
    """Memoize the source reading of Taichi's front end (`_get_tree_and_ctx` and the kernel checker): the
    names `getsourcefile`, `getsourcelines` and `textwrap` in the modules that use them (once)."""
    try:
        from taichi.lang import kernel_impl
        from taichi.lang.ast import checkers
    except ImportError:
        return
    for module in (kernel_impl, checkers):
        for name in ("getsourcefile", "getsourcelines"):
            current = getattr(module, name, None)
            if current is not None and getattr(current, "taichi_original", None) is None:
                setattr(module, name, _memo_by_code(current))
    if not isinstance(getattr(kernel_impl, "textwrap", None), (_MemoTextwrap, type(None))):
        kernel_impl.textwrap = _MemoTextwrap(kernel_impl.textwrap)


def original_get_pos_info():
    """Taichi's own method (for the comparison test), installed or not."""
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    current = ASTTransformerContext.get_pos_info
    return getattr(current, "taichi_original", current)
