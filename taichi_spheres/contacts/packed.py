"""Packed rows of the serial solve (contacts/pgs.py sweep_scheduled).

A serial solve sweeps its rows in one list, colour by colour (pgs.schedule_rows): a
row is read through that list from fields laid out cell by cell. Before each pass
(velocity, then position) the rows' spheres, normals, effective masses, targets and
accumulated impulses are copied into fields of their own in the list's order, so
that every sweep of the pass reads them one after the other, without the list and
its index arithmetic; after the velocity pass the accumulated impulses go back to
their rows (the finish keeps them for the warm start; nothing reads the position
pass's after it). The same updates in the same order: the same bits (docs/bench.md,
"Packed rows and halved residuals", measures what they save).

Frictional rows are swept from their own fields (friction_rows.py), and an engine
with more room than engine.capacity_for makes for a scene just below the default
Performance.serial_solver_below is made for scenes that sweep in parallel: neither
keeps packed rows (packs_rows). A Simulation that asks such an engine for a serial
solve gets the same sweeps through the list.

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti

from ..config import Performance
from ..state import Features

__all__ = ["PackedRows", "packs_rows", "packed_row_bytes"]


def packs_rows(features: Features, spheres: int, cpu: bool) -> bool:
    """Whether the contact solver of an engine with room for ``spheres`` keeps packed
    rows (module docstring): on the CPU, with contacts and without friction, where
    the room is at most what a new engine makes for a scene just below the default
    Performance.serial_solver_below (the scenes that solve serially by default)."""
    from ..engine import MIN_SPHERES, capacity_for   # (engine imports the solver)
    largest = capacity_for(Performance().serial_solver_below - 1, MIN_SPHERES)
    return cpu and features.contacts and not features.friction and spheres <= largest


def packed_row_bytes(real: int) -> int:
    """Bytes of one packed row with ``real``-byte floats: a, b (i32), normal (3),
    effective mass, target and accumulated impulse."""
    return 2 * 4 + 6 * real


class PackedRows:
    """The packed copies of the rows (module docstring).

    Fields (K rows, only where packs_rows): pack_a, pack_b: (K,) i32; pack_n: (K,)
    vec3; pack_meff, pack_goal, pack_acc: (K,) real — row_a, row_b, normal, meff, the
    pass's target and accumulated impulse of the row at schedule[t], at t."""

    def allocate_packed(self, rows: int):
        """The packed fields for ``rows`` rows where self.packed (packs_rows), else
        None."""
        real, on = self.real, self.packed
        self.pack_a = ti.field(ti.i32, shape=rows) if on else None
        self.pack_b = ti.field(ti.i32, shape=rows) if on else None
        self.pack_n = ti.Vector.field(3, real, shape=rows) if on else None
        self.pack_meff = ti.field(real, shape=rows) if on else None
        self.pack_goal = ti.field(real, shape=rows) if on else None
        self.pack_acc = ti.field(real, shape=rows) if on else None

    @ti.func
    def pack_rows(self, goal: ti.template(), acc: ti.template(), spheres: ti.template()):
        """Copy every scheduled row's normal, target ``goal`` and accumulated impulse
        ``acc`` to its place in the schedule, with ``spheres`` its spheres and effective
        mass too (the velocity pass; the position pass finds them there: the rows'
        spheres and masses do not change in a step, their normals do) (kernel top
        level, one serial task)."""
        if ti.static(self.packed):
            ti.loop_config(serialize=True)
            for t in range(self.schedule_start[self.n_colours_f[None]]):
                s = self.schedule[t]
                if ti.static(spheres):
                    self.pack_a[t] = self.row_a[s]
                    self.pack_b[t] = self.row_b[s]
                    self.pack_meff[t] = self.meff[s]
                self.pack_n[t] = self.normal[s]
                self.pack_goal[t] = goal[s]
                self.pack_acc[t] = acc[s]

    @ti.func
    def unpack_impulses(self, acc: ti.template()):
        """The packed accumulated impulses back to their rows' ``acc`` (kernel top
        level, one serial task)."""
        if ti.static(self.packed):
            ti.loop_config(serialize=True)
            for t in range(self.schedule_start[self.n_colours_f[None]]):
                acc[self.schedule[t]] = self.pack_acc[t]

    @ti.func
    def update_packed(self, t, field: ti.template(), omega, violation: ti.template() = False):
        """pgs.update_from on the packed row t (the schedule's t-th) with relaxation
        ``omega``, on velocities or pseudo-velocities ``field`` ((N,) vec3 [m/s]);
        returns its residual [m/s] (halved where halved_residual; with ``violation``, the
        overlap it met)."""
        return self.update_from(t, self.pack_a, self.pack_b, self.pack_n, self.pack_meff,
                                field, self.pack_acc, self.pack_goal, omega, violation)
