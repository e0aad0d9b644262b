"""Sinks in the engine's fields: the spheres whose centre is in a sink taken out in one
launch, the others moved down to close the gap (walls.py counts them in the drift;
with a recycling sink discharge.py removes them on the host instead).

:class:`SinkTakeOut` does in the fields what ``discharge.discharge`` followed by
``Engine.keep_spheres`` does through the host for sinks that do not recycle. The
spheres that stay are numbered in chunks of CHUNK spheres: each chunk counts its
spheres in sinks, one thread scans the counts, and each chunk then numbers its own
(``new_index``: the same numbers, in the same order, as one pass over every sphere).
Each staying sphere's position, velocity, spin, radius, inverse mass and inertia,
material and warm-start rows (partners renumbered, contacts/warm_table.py) then go
down to its new index: where the light loops run serially (the CPU below
Performance.serial_light_below spheres), in one pass in increasing order, so that no
row is overwritten before it is read; in parallel (a GPU, or a large system on the
CPU) through a scratch copy of the spheres from the first one taken on
(:class:`StayerScratch`), put there by one parallel loop and taken back by another.
Only the taken spheres' rows come back to the host, for the discharged energy; the
remaining spheres' largest squared speed goes to params.vmax2 (Motion.measure_vmax's
body), and the detection's pending pairs are forgotten as Contacts.bind forgets them
(forget_pending). The same bits as the host's way (tests/test_discharge.py) without
reading and loading every sphere's rows, its warm-start table and the scene's
constants.
"""

import numpy as np
import taichi as ti

from .contacts.warm_table import WARM_FIELDS, copy_warm_row
from .state import SPHERE_FIELDS, copy_sphere

__all__ = ["SinkTakeOut", "StayerScratch"]

#: columns of a taken sphere's row: x, v, omega [m, m/s, rad/s]
ROW_WIDTH = 9
#: spheres one thread numbers when the take-out runs in parallel
CHUNK = 256


@ti.data_oriented
class StayerScratch:
    """Where the spheres that stay wait on their way to their new index in a parallel
    take-out: the fields of ``state`` that copy_sphere moves and, with a contact
    solver, its warm-start table and the loaded and near flags (the same names,
    shapes and types; None where they are None)."""

    def __init__(self, state, solver):
        for name in SPHERE_FIELDS:
            setattr(self, name, _like(getattr(state, name)))
        for name in WARM_FIELDS:
            setattr(self, name, _like(getattr(solver, name)) if solver is not None else None)
        self.loaded = _like(state.loaded) if solver is not None else None
        self.near = _like(state.near) if solver is not None else None


def _like(field):
    """A new field of the shape, type and vector size of ``field`` (None for None)."""
    if field is None:
        return None
    if isinstance(field, ti.MatrixField):
        return ti.Vector.field(field.n, field.dtype, shape=field.shape)
    return ti.field(field.dtype, shape=field.shape)


@ti.data_oriented
class SinkTakeOut:
    """The take-out kernel over an engine's state, params, motion, contacts and contact
    solver (None without one). ``run()`` returns the taken spheres' indices (k,) and
    their rows (k, 9) in the fields' precision, in increasing index."""

    def __init__(self, state, params, motion, contacts, solver, serial: bool):
        self.state = state
        self.params = params
        self.motion = motion
        self.contacts = contacts
        self.solver = solver
        self.has_solver = solver is not None
        self.serial = serial
        cap = state.capacity
        self.new_index = ti.field(ti.i32, shape=cap)    # -1: taken out
        self.n_taken = ti.field(ti.i32, shape=())
        self.first_taken = ti.field(ti.i32, shape=())  # the lowest index taken out
        self.chunk_taken = ti.field(ti.i32, shape=(cap + CHUNK - 1) // CHUNK)
        self.scratch = None if serial else StayerScratch(state, solver)
        self._taken = np.zeros(cap, dtype=np.int32)
        self._rows = np.zeros((cap, ROW_WIDTH), dtype=state._np_real)
        real = state.real

        # a closure, not a method kernel (no per-launch dispatch of ``self``)
        @ti.kernel
        def take_out(taken: ti.types.ndarray(dtype=ti.i32, ndim=1),
                     rows: ti.types.ndarray(dtype=real, ndim=2)) -> ti.i32:
            self.number_the_stayers(taken, rows)
            if ti.static(serial):
                self.move_the_stayers()
            else:
                self.stage_the_stayers()
                self.unstage_the_stayers()
            self.empty_the_rest()
            state.n_spheres[None] -= self.n_taken[None]
            self.motion._measure_vmax_body()
            self.contacts.forget_pending()
            return self.n_taken[None]

        self._take_out = take_out

    def run(self):
        """Take the spheres in sinks out of the fields; returns (indices (k,) i32,
        rows (k, 9): x, v, omega of each, in the fields' precision) of the k taken."""
        k = self._take_out(self._taken, self._rows)
        return self._taken[:k].copy(), self._rows[:k].copy()

    @ti.func
    def number_the_stayers(self, taken: ti.template(), rows: ti.template()):
        """new_index[i]: sphere i's index after the take-out, -1 when its centre is in a
        sink; the taken ones' indices and rows to ``taken`` and ``rows`` in increasing
        index, the lowest to first_taken (n_spheres if none) (kernel top level): chunks
        of CHUNK spheres count theirs, one thread scans the counts, each chunk numbers
        its own."""
        n = self.state.n_spheres[None]
        chunks = (n + CHUNK - 1) // CHUNK
        ti.loop_config(serialize=ti.static(self.serial))
        for c in range(chunks):
            count = 0
            for i in range(c * CHUNK, ti.min(c * CHUNK + CHUNK, n)):
                if self.params.in_a_sink(self.state.x[i]):
                    count += 1
            self.chunk_taken[c] = count
        ti.loop_config(serialize=True)
        for _ in range(1):
            total = 0
            for c in range(chunks):
                count = self.chunk_taken[c]
                self.chunk_taken[c] = total
                total += count
            self.n_taken[None] = total
            self.first_taken[None] = n
        ti.loop_config(serialize=ti.static(self.serial))
        for c in range(chunks):
            k = self.chunk_taken[c]
            for i in range(c * CHUNK, ti.min(c * CHUNK + CHUNK, n)):
                if self.params.in_a_sink(self.state.x[i]):
                    if k == 0:
                        self.first_taken[None] = i
                    self.keep_taken_row(taken, rows, k, i)
                    self.new_index[i] = -1
                    k += 1
                else:
                    self.new_index[i] = i - k

    @ti.func
    def keep_taken_row(self, taken: ti.template(), rows: ti.template(), k, i):
        """Sphere i, the k-th taken out: its index and x, v, omega to taken[k], rows[k]."""
        taken[k] = i
        for a in ti.static(range(3)):
            rows[k, a] = self.state.x[i][a]
            rows[k, 3 + a] = self.state.v[i][a]
            if ti.static(self.state.features.friction):
                rows[k, 6 + a] = self.state.omega[i][a]
            else:
                rows[k, 6 + a] = 0

    @ti.func
    def move_the_stayers(self):
        """Each staying sphere to its new index, in increasing index (new index <= old:
        nothing is overwritten before it is read) (kernel top level)."""
        n_old = self.state.n_spheres[None]
        ti.loop_config(serialize=True)
        for i in range(n_old):
            j = self.new_index[i]
            if j >= 0 and j < i:
                self.state.move_sphere(i, j)
            if ti.static(self.has_solver):
                if j >= 0:
                    self.solver.move_warm_row(i, j, self.new_index, n_old)

    @ti.func
    def stage_the_stayers(self):
        """The parallel move's first half (kernel top level): each staying sphere from
        first_taken on, and its warm-start rows, to its new index in the scratch; the
        warm-start rows of those before it renumbered where they are (each thread
        touches its own sphere's row)."""
        n_old = self.state.n_spheres[None]
        first = self.first_taken[None]
        for i in range(n_old):
            j = self.new_index[i]
            if j >= 0 and i >= first:
                copy_sphere(self.state, i, self.scratch, j)
                if ti.static(self.has_solver):
                    copy_warm_row(self.solver, self.state, i, self.scratch, self.scratch, j,
                                  self.new_index, n_old)
            elif j >= 0:
                if ti.static(self.has_solver):
                    self.solver.move_warm_row(i, i, self.new_index, n_old)

    @ti.func
    def unstage_the_stayers(self):
        """The parallel move's second half (kernel top level): the scratch's spheres and
        warm-start rows, first_taken to the new count, back to the fields."""
        n_new = self.state.n_spheres[None] - self.n_taken[None]
        for j in range(self.first_taken[None], n_new):
            copy_sphere(self.scratch, j, self.state, j)
            if ti.static(self.has_solver):
                copy_warm_row(self.scratch, self.scratch, j, self.solver, self.state, j,
                              self.new_index, 0)

    @ti.func
    def empty_the_rest(self):
        """The warm-start rows of the indices no sphere holds any more (kernel top
        level)."""
        if ti.static(self.has_solver):
            n_old = self.state.n_spheres[None]
            for i in range(n_old - self.n_taken[None], n_old):
                self.solver.empty_warm_row(i)
