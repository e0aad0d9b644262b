"""Sinks in the engine's fields: the spheres whose centre is in a sink taken out in one
launch, the others moved down to close the gap (walls.py counts them in the drift;
with a recycling sink, or on a GPU, discharge.py removes them on the host instead).

:class:`SinkTakeOut` does in the fields what ``discharge.discharge`` followed by
``Engine.keep_spheres`` does through the host for sinks that do not recycle: one
serial pass numbers the spheres that stay (``new_index``), a second moves each one's
position, velocity, spin, radius, inverse mass and inertia, material and warm-start
rows (partners renumbered, contacts/warm_table.py) down to its new index in increasing
order, so that no row is overwritten before it is read. Only the taken spheres' rows
come back to the host, for the discharged energy; the remaining spheres' largest
squared speed goes to params.vmax2 (Motion.measure_vmax's body), and the detection's
pending pairs are forgotten as Contacts.bind forgets them (forget_pending). The same bits
as the host's way (tests/test_discharge.py) without reading and loading every
sphere's rows, its warm-start table and the scene's constants.
"""

import numpy as np
import taichi as ti

__all__ = ["SinkTakeOut"]

#: columns of a taken sphere's row: x, v, omega [m, m/s, rad/s]
ROW_WIDTH = 9


@ti.data_oriented
class SinkTakeOut:
    """The take-out kernel over an engine's state, params, motion, contacts and contact
    solver (None without one). ``run()`` returns the taken spheres' indices (k,) and
    their rows (k, 9) in the fields' precision, in increasing index."""

    def __init__(self, state, params, motion, contacts, solver):
        self.state = state
        self.params = params
        self.motion = motion
        self.contacts = contacts
        self.solver = solver
        self.has_solver = solver is not None
        cap = state.capacity
        self.new_index = ti.field(ti.i32, shape=cap)    # -1: taken out
        self.n_taken = ti.field(ti.i32, shape=())
        self._taken = np.zeros(cap, dtype=np.int32)
        self._rows = np.zeros((cap, ROW_WIDTH), dtype=state._np_real)
        real = state.real

        # a closure, not a method kernel (no per-launch dispatch of ``self``)
        @ti.kernel
        def take_out(taken: ti.types.ndarray(dtype=ti.i32, ndim=1),
                     rows: ti.types.ndarray(dtype=real, ndim=2)) -> ti.i32:
            self.number_the_stayers(taken, rows)
            self.move_the_stayers()
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
        sink; the taken ones' indices and rows to ``taken`` and ``rows`` in order
        (kernel top level)."""
        self.n_taken[None] = 0
        ti.loop_config(serialize=True)
        for i in range(self.state.n_spheres[None]):
            if self.params.in_a_sink(self.state.x[i]):
                k = self.n_taken[None]
                taken[k] = i
                for a in ti.static(range(3)):
                    rows[k, a] = self.state.x[i][a]
                    rows[k, 3 + a] = self.state.v[i][a]
                    if ti.static(self.state.features.friction):
                        rows[k, 6 + a] = self.state.omega[i][a]
                    else:
                        rows[k, 6 + a] = 0
                self.new_index[i] = -1
                self.n_taken[None] = k + 1
            else:
                self.new_index[i] = i - self.n_taken[None]

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
    def empty_the_rest(self):
        """The warm-start rows of the indices no sphere holds any more (kernel top
        level)."""
        if ti.static(self.has_solver):
            n_old = self.state.n_spheres[None]
            for i in range(n_old - self.n_taken[None], n_old):
                self.solver.empty_warm_row(i)
