"""hostload.FieldLoad: an engine's host-loaded fields written in one kernel hold the
values, to the bit, that Python-scope writes of each field give."""
import numpy as np
import pytest
import taichi as ti

from taichi_spheres import runtime
from taichi_spheres.hostload import FieldLoad


class _Part:
    """A part with 0-d and small fields of the runtime's precision and i32."""

    def __init__(self, real):
        self.a = ti.field(real, shape=())
        self.v = ti.Vector.field(3, real, shape=())
        self.n = ti.Vector.field(3, ti.i32, shape=())
        self.table = ti.Vector.field(3, real, shape=(4,))
        self.grid = ti.field(real, shape=(2, 3))
        self.rows = ti.Vector.field(3, ti.i32, shape=(5, 2))

    @staticmethod
    def loaded_fields():
        return ("a", "v", "n", "table", "grid", "rows")


def test_one_launch_writes_the_bits_of_python_scope_writes(arch, precision):
    rt = runtime.ensure(arch, precision)
    real = ti.f64 if rt.precision == "f64" else ti.f32
    part, other = _Part(real), _Part(real)
    ref = _Part(real)
    load = FieldLoad((part, other), real)
    values = dict(a=0.1, v=[1 / 3, -2e-7, 1e30], n=[1, -2, 30000001],
                  table=np.arange(12).reshape(4, 3) * 0.1,
                  grid=np.arange(6).reshape(2, 3) / 7,
                  rows=np.arange(30).reshape(5, 2, 3) - 4)
    load.write(part, **values)
    load.write(other, **{**values, "a": 2.5})
    ref.a[None] = values["a"]
    ref.v[None] = values["v"]
    for name in ("a", "v"):
        assert getattr(part, name).to_numpy().tobytes() == getattr(ref, name).to_numpy().tobytes()
    assert list(part.n[None]) == values["n"]
    dtype = np.float64 if real == ti.f64 else np.float32
    for name in ("table", "grid"):
        assert getattr(part, name).to_numpy().tobytes() == values[name].astype(dtype).tobytes()
    assert np.array_equal(part.rows.to_numpy(), values["rows"])
    assert other.a[None] == 2.5
    # a write of some fields keeps the others as last written
    load.write(part, a=-1.0)
    assert part.a[None] == -1.0 and list(part.n[None]) == values["n"] and other.a[None] == 2.5


def test_unknown_fields_and_wrong_sizes_are_refused(arch):
    rt = runtime.ensure(arch)
    real = ti.f64 if rt.precision == "f64" else ti.f32
    part = _Part(real)
    load = FieldLoad((part,), real)
    with pytest.raises(KeyError, match="_Part.b is not a loaded field"):
        load.write(part, b=1.0)
    with pytest.raises(ValueError, match="field 'v' takes 3 values, got 2"):
        load.write(part, v=[1.0, 2.0])


def test_no_kernel_writes_a_field_the_engine_loads_from_the_host(arch):
    """FieldLoad writes every field of its set from the host's copy on each write, so no
    kernel may change one: after steps of a scene with walls, gravity, friction,
    geometry objects and a sink, every loaded field still holds its host copy."""
    import os
    import taichi_spheres as ts
    scene = ts.load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes", "silo.toml"))
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(0.05)
    load = sim._engine.host_load
    checked = 0
    for (part, name), field, host in load.host_values():
        assert field.to_numpy().tobytes() == host.astype(field.to_numpy().dtype).tobytes(), \
            f"{part}.{name}"
        checked += 1
    assert checked >= 40 and sim.stats["steps"] > 0
