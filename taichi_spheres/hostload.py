"""Loading a part's small fields from the host in one kernel launch.

A Python-scope write of a Taichi field (``f[None] = x``, ``f.from_numpy(a)``, ``f.fill(x)``)
compiles a small kernel of its own for that field on its first use. An engine's parts
load some forty scalars and a few small tables when a Simulation binds them; an
engine's :class:`FieldLoad` writes all of them in one kernel, compiled once per engine
(engine.py; what it saves: docs/bench.md, "Kernel compiles").
"""

import math

import numpy as np
import taichi as ti
from taichi.lang.matrix import MatrixField

__all__ = ["FieldLoad"]


def _layout(field):
    """(is_int, shape, width) of a field: whether it holds i32, its index shape and the
    vector width (0 for a scalar field)."""
    width = 0
    if isinstance(field, MatrixField):
        if field.m != 1:
            raise TypeError(f"FieldLoad takes scalar and vector fields, not {field.n}x{field.m}")
        width = field.n
    return field.dtype == ti.i32, tuple(field.shape), width


class FieldLoad:
    """The fields that ``parts`` load from the host (each part's ``loaded_fields()``: the
    names of 0-d or small fields of ``real`` or i32, scalars or vectors), written in one
    kernel launch (compiled on the first :meth:`write`) instead of a kernel per field.
    The host keeps a copy of every value: a write of some of a part's fields writes
    the others again as last written (zero before), so no field here may be written
    by a kernel. Reals are rounded to ``real`` by numpy's cast, as a Python-scope write
    rounds them (to nearest): the fields hold the same bits."""

    def __init__(self, parts, real):
        self.np_real = np.float64 if real == ti.f64 else np.float32
        fields, layout, offsets = [], [], []
        self.index = {}     # (id(part), name): the field's place in fields
        self.names = []     # (part's class, field name) of each field, in order
        sizes = [0, 0]      # reals, ints
        for part in parts:
            for name in part.loaded_fields():
                field = getattr(part, name)
                kind = _layout(field)
                if not kind[0] and field.dtype != real:
                    raise TypeError(f"field {name!r} holds {field.dtype}, not {real} or i32")
                self.index[(id(part), name)] = len(fields)
                self.names.append((type(part).__name__, name))
                fields.append(field)
                layout.append(kind)
                offsets.append(sizes[kind[0]])
                sizes[kind[0]] += _size(kind)
        self.reals = np.zeros(max(sizes[0], 1), dtype=self.np_real)
        self.ints = np.zeros(max(sizes[1], 1), dtype=np.int32)
        self.fields, self.layout, self.offsets = tuple(fields), tuple(layout), tuple(offsets)
        self._kernel = self._build(self.fields, self.layout, self.offsets, real)

    def host_values(self) -> list:
        """((part's class, name), field, host copy of its values as the field's numpy
        array) of every field of the set, in order."""
        out = []
        for key, field, (is_int, shape, width), at in zip(self.names, self.fields,
                                                         self.layout, self.offsets):
            flat = (self.ints if is_int else self.reals)[at:at + _size((is_int, shape, width))]
            out.append((key, field, flat.reshape(shape + ((width,) if width else ()))))
        return out

    def write(self, part, **values) -> None:
        """Load ``part``'s fields named in ``values`` (a number for a scalar field, an
        array of the field's shape, x its vector width, for the others) and write
        every field of the set."""
        for name, value in values.items():
            k = self.index.get((id(part), name))
            if k is None:
                raise KeyError(f"{type(part).__name__}.{name} is not a loaded field")
            is_int, at, size = self.layout[k][0], self.offsets[k], _size(self.layout[k])
            flat = np.asarray(value, dtype=np.int64 if is_int else np.float64).reshape(-1)
            if flat.size != size:
                raise ValueError(f"field {name!r} takes {size} values, got {flat.size}")
            if is_int:
                self.ints[at:at + size] = flat
            else:
                self.reals[at:at + size] = flat.astype(self.np_real)
        self._kernel(self.reals, self.ints)

    @staticmethod
    def _build(fields, layout, offsets, real):
        # the 0-d fields' values as unrolled stores (in static loops of at most 32:
        # Taichi warns above), the other fields' in one loop over all their values
        # (a loop per field, or all unrolled, compiles slower)
        stores = [store for k in range(len(fields)) if not layout[k][1]
                  for store in _stores(k, layout[k], offsets[k])]
        chunks = [stores[c:c + 32] for c in range(0, len(stores), 32)]
        tables = [k for k in range(len(fields)) if layout[k][1]]
        starts, ends, total = [], [], 0         # in elements (values / width)
        for k in tables:
            starts.append(total)
            total += math.prod(layout[k][1])
            ends.append(total)

        @ti.kernel
        def load_fields(reals: ti.types.ndarray(dtype=real, ndim=1),
                        ints: ti.types.ndarray(dtype=ti.i32, ndim=1)):
            for c in ti.static(range(len(chunks))):
                for s in ti.static(range(len(chunks[c]))):
                    _store(fields[chunks[c][s][0]], chunks[c][s], reals, ints)
            for t in range(total):
                for m in ti.static(range(len(tables))):
                    k = ti.static(tables[m])
                    if starts[m] <= t < ends[m]:
                        _store_element(fields[k], layout[k], offsets[k], t - starts[m],
                                       reals, ints)

        return load_fields


def _size(layout):
    """The values a field of ``layout`` (is_int, shape, width) holds."""
    return math.prod(layout[1]) * max(layout[2], 1)


def _stores(k, layout, at):
    """The stores of 0-d field k: (k, component (-1 for a scalar field), is_int,
    position in its host array)."""
    is_int, _, width = layout
    return [(k, comp, is_int, at + max(comp, 0)) for comp in
            (range(width) if width else [-1])]


@ti.func
def _store(field: ti.template(), store: ti.template(), reals: ti.template(),
           ints: ti.template()):
    """One value from ``ints`` (an i32 field) or ``reals`` into 0-d ``field`` (_stores)."""
    comp, is_int, at = ti.static(store[1], store[2], store[3])
    src = ti.static(ints if is_int else reals)
    if ti.static(comp < 0):
        field[None] = src[at]
    else:
        field[None][comp] = src[at]


@ti.func
def _store_element(field: ti.template(), layout: ti.template(), at: ti.template(), element,
                   reals: ti.template(), ints: ti.template()):
    """Element ``element`` (row-major) of ``field``, its components one after the other,
    from position at + element x width of ``ints`` (an i32 field) or ``reals``."""
    is_int, shape, width = ti.static(layout)
    src = ti.static(ints if is_int else reals)
    strides = ti.static(_strides(shape))
    rest = element
    index = ti.Vector.zero(ti.i32, ti.static(len(shape)))
    for d in ti.static(range(len(shape))):
        index[d] = rest // strides[d]
        rest = rest % strides[d]
    if ti.static(width == 0):
        field[index] = src[at + element]
    else:
        for comp in ti.static(range(width)):
            field[index][comp] = src[at + element * width + comp]


def _strides(shape):
    """Row-major strides of the elements of a field of ``shape``."""
    return tuple(math.prod(shape[d + 1:]) for d in range(len(shape)))
