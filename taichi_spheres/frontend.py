"""Faster kernel compiles: Taichi's Python frontend looks the same things up again and
again, and here it looks them up once.

Before Taichi compiles (or finds in its offline cache) a kernel, its frontend turns the
Python source of the kernel and of every ``ti.func`` it calls into Taichi's IR. For
each function it reads the source with ``inspect`` (tokenising the whole block), and
for each call, loop and assignment it formats a position message (file, line and the
source line underlined, wrapped with ``textwrap``) that Taichi keeps for its error
messages. The engine's ``ti.func`` bodies are inlined into many kernels and every
engine variant compiles them again, so the same functions are read and the same
positions formatted thousands of times. Remembering them takes 13-53 % off the first
step of a fresh process whose kernels Taichi's offline cache already holds, and 13-39 %
off a second engine variant compiled in one process (the test suite's case); a cold
first compile is mostly LLVM's (``tools/compile_frontend.py``, docs/bench.md
"Compile frontend").

:func:`memoize_source_lookups` remembers both: the source of each code object (with
its file name: equal code from two files compares equal), and each position's message
by the function's source text, file, offsets, name, node type and line and column
span, everything the message is made of. The strings are the ones Taichi makes, so
kernels, error messages and bits do not change. Installed once per process by
``runtime.ensure`` before Taichi is initialised; with a Taichi whose frontend lacks
these functions (other than the 1.7 this package requires) nothing is changed.
"""
from __future__ import annotations

__all__ = ["memoize_source_lookups", "installed"]

_installed = False


def installed() -> bool:
    """True once :func:`memoize_source_lookups` has wrapped Taichi's lookups."""
    return _installed


def memoize_source_lookups() -> bool:
    """Wrap Taichi's source reading (kernel_impl.getsourcelines, getsourcefile) and
    position messages (ASTTransformerContext.get_pos_info) with memos; idempotent.
    Returns whether they are wrapped."""
    global _installed
    if _installed:
        return True
    try:
        from taichi.lang import kernel_impl
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
        originals = (kernel_impl.getsourcelines, kernel_impl.getsourcefile,
                     ASTTransformerContext.get_pos_info)
    except (ImportError, AttributeError):
        return False
    lines_of, file_of, pos_info = originals
    kernel_impl.getsourcelines = _per_code(lines_of, copy=lambda out: (list(out[0]), out[1]))
    kernel_impl.getsourcefile = _per_code(file_of, copy=lambda out: out)
    ASTTransformerContext.get_pos_info = _per_position(pos_info)
    _installed = True
    return True


def _per_code(lookup, copy):
    """``lookup(obj)`` remembered per code object of ``obj`` (a function) and its file
    name (code objects compare by their contents, not their file); ``copy`` hands each
    caller its own copy of a mutable result. Objects without code are looked up each
    time."""
    memo = {}

    def remembered(obj):
        code = getattr(obj, "__code__", None)
        if code is None:
            return lookup(obj)
        key = (code.co_filename, code)
        if key not in memo:
            memo[key] = lookup(obj)
        return copy(memo[key])

    remembered.__wrapped__ = lookup
    remembered.memo = memo
    return remembered


#: attribute under which a transformer context keeps its source text (one string per
#: context, so that its hash is computed once)
_SOURCE_KEY = "_taichi_spheres_source"


def _per_position(format_position):
    """``format_position(ctx, node)`` remembered per (function source text, file, line
    offset, indent, function name, node type, line and column span): everything the
    message reads (ASTTransformerContext.get_pos_info: the source lines over the node's
    span, for a loop, ``if`` or ``def`` up to its body's first line, which the source
    and the span fix)."""
    memo = {}

    def remembered(ctx, node):
        source = ctx.__dict__.get(_SOURCE_KEY)
        if source is None:
            source = ctx.__dict__[_SOURCE_KEY] = "\n".join(ctx.src)
        key = (source, ctx.file, ctx.lineno_offset, ctx.indent, ctx.func.func.__name__,
               type(node).__name__, node.lineno, node.end_lineno, node.col_offset,
               node.end_col_offset)
        out = memo.get(key)
        if out is None:
            out = memo[key] = format_position(ctx, node)
        return out

    remembered.__wrapped__ = format_position
    remembered.memo = memo
    return remembered
