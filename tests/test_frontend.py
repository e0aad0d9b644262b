"""The frontend memos (taichi_spheres/frontend.py): installed with the runtime, and
they hand Taichi exactly what its own lookups give."""
import importlib.util

import numpy as np
import pytest

from taichi_spheres import frontend, runtime


def _installed(arch):
    """Start the runtime (which installs the memos) at the arch's default precision;
    skip where TAICHI_SPHERES_FRONTEND_MEMO turns them off."""
    if not runtime.frontend_memos_wanted():
        pytest.skip("the memos are turned off (TAICHI_SPHERES_FRONTEND_MEMO=off)")
    runtime.ensure(arch)
    assert frontend.installed()


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
    def second() -> float:
        out = 0.0
        for i in field:
            out += twice(i)
        return out

    return first, second


def test_memos_give_taichis_own_source_and_position_messages(arch, monkeypatch):
    """Every position message and source lookup made while compiling two kernels that
    inline one ti.func equals what Taichi's own functions return for the same node and
    function, and some of them came from the memos (the func's positions again); the
    kernels compute as written."""
    import taichi as ti
    from taichi.lang import kernel_impl
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    _installed(arch)
    memo_pos = ASTTransformerContext.get_pos_info
    lookups = {"getsourcelines": kernel_impl.getsourcelines,
               "getsourcefile": kernel_impl.getsourcefile}
    seen_pos, seen = [], []

    def recording_pos(ctx, node):
        out = memo_pos(ctx, node)
        seen_pos.append((ctx, node, out))
        return out

    def recording(name):
        def lookup(obj):
            out = lookups[name](obj)
            seen.append((name, obj, out))
            return out
        return lookup

    monkeypatch.setattr(ASTTransformerContext, "get_pos_info", recording_pos)
    for name in lookups:
        monkeypatch.setattr(kernel_impl, name, recording(name))
    positions_before = len(memo_pos.memo)
    field = ti.field(float, shape=4)
    field.from_numpy(np.arange(4.0))
    first, second = _double(ti, field)
    first()
    total = second()
    np.testing.assert_array_equal(field.to_numpy(), 2.0 * np.arange(4.0) + 1.0)
    assert total == float(np.sum(2.0 * (2.0 * np.arange(4.0) + 1.0) + 1.0))
    assert len(seen_pos) > 10 and {name for name, _, _ in seen} == set(lookups)
    assert len(memo_pos.memo) - positions_before < len(seen_pos)
    for ctx, node, out in seen_pos:
        assert out == memo_pos.__wrapped__(ctx, node)
    for name, obj, out in seen:
        assert out == lookups[name].__wrapped__(obj)


def test_equal_code_in_two_files_keeps_its_own_source(arch, tmp_path):
    """Two files defining the same function at the same line, differing only in a
    comment (their code objects compare equal): each lookup gives its own file and
    lines."""
    from taichi.lang import kernel_impl

    _installed(arch)
    funcs = {}
    for name in ("first", "second"):
        path = tmp_path / f"{name}_module.py"
        path.write_text(f"def shift(x):\n    return x + 1  # {name}\n")
        spec = importlib.util.spec_from_file_location(f"{name}_module", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        funcs[name] = (module.shift, str(path))
    assert funcs["first"][0].__code__ == funcs["second"][0].__code__
    for name, (func, path) in funcs.items():
        lines, start = kernel_impl.getsourcelines(func)
        assert start == 1 and lines[1].endswith(f"# {name}\n")
        assert kernel_impl.getsourcefile(func) == path
