"""The frontend memos (taichi_spheres/frontend.py): installed with the runtime, and
they hand Taichi exactly what its own lookups give."""
import os

import numpy as np
import pytest

from taichi_spheres import frontend, runtime


def _double(ti, field):
    """A ti.func and two kernels that inline it: the second kernel's compile reads the
    func's source and formats its positions again."""

    @ti.func
    def twice(i):
        return 2.0 * field[i] + 1.0

    @ti.kernel
    def first():
        for i in field:
            field[i] = twice(i)

    @ti.kernel
    def second() -> ti.f64:
        out = 0.0
        for i in field:
            out += twice(i)
        return out

    return first, second


def test_memos_give_taichis_own_source_and_position_messages(arch, monkeypatch):
    """Every position message and source lookup made while compiling two kernels that
    inline one ti.func (the second from the memos) equals what Taichi's own functions
    return for the same node and function; the kernels compute as written."""
    import taichi as ti
    from taichi.lang import kernel_impl
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    if os.environ.get(runtime.FRONTEND_MEMO_ENV, "").strip().lower() == "off":
        pytest.skip("the memos are turned off (TAICHI_SPHERES_FRONTEND_MEMO=off)")
    runtime.ensure(arch, "f64")
    assert frontend.installed()
    memo_pos = ASTTransformerContext.get_pos_info
    memo_lines = kernel_impl.getsourcelines
    seen_pos, seen_lines = [], []

    def recording_pos(ctx, node):
        out = memo_pos(ctx, node)
        seen_pos.append((ctx, node, out))
        return out

    def recording_lines(obj):
        out = memo_lines(obj)
        seen_lines.append((obj, out))
        return out

    monkeypatch.setattr(ASTTransformerContext, "get_pos_info", recording_pos)
    monkeypatch.setattr(kernel_impl, "getsourcelines", recording_lines)
    field = ti.field(ti.f64, shape=4)
    field.from_numpy(np.arange(4.0))
    first, second = _double(ti, field)
    first()
    total = second()
    np.testing.assert_array_equal(field.to_numpy(), 2.0 * np.arange(4.0) + 1.0)
    assert total == float(np.sum(2.0 * (2.0 * np.arange(4.0) + 1.0) + 1.0))
    assert len(seen_pos) > 10 and len(seen_lines) >= 3
    for ctx, node, out in seen_pos:
        assert out == memo_pos.__wrapped__(ctx, node)
    for obj, out in seen_lines:
        assert out == memo_lines.__wrapped__(obj)
