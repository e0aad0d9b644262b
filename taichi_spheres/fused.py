"""The whole step in one or two kernels, for small systems on the CPU (:class:`FusedStep`).

No ``from __future__ import annotations`` here: Taichi reads kernel argument
annotations as objects.
"""

import typing

import taichi as ti

from .contacts import Contacts
from .grid import Grid
from .projection import Projection
from .walls import Motion


class FusedOutcome(typing.NamedTuple):
    """What a fused step did: the sweeps it ran; ``rebuild``: it stopped because a
    sphere moved farther than the grid's slack (go on kernel by kernel after a
    rebuild); ``project``: the overlap projection is due."""

    sweeps: int
    rebuild: bool
    project: bool


class FusedStep:
    """A whole step of a small system on the CPU, where every loop runs serially
    anyway, in one kernel launch (two when the projection is due) besides the counter
    read-back, instead of 3 + one per sweep + 3 per projection iteration (each ~30-50
    us, which dominate a step of a few thousand spheres: in ``tools/peer_lammps.py``,
    1,000 spheres piling on the floor ran 1.19 instead of 1.72 wall s per simulated s).

    ``step(h, max_sweeps)``: drift and walls, grid build, detection, detect/resolve
    sweeps until no approaching overlap is left or ``max_sweeps``, or until a sphere
    moved farther than the grid's slack (the grid must be rebuilt: the caller goes on
    kernel by kernel, a rare case); returns a FusedOutcome: the sweeps, whether it
    stopped for a rebuild, and whether the overlap projection is due (overlap above
    ``tolerance`` after a step that hit the sweep limit, without a contact solver:
    ``solver_on`` False), as :meth:`Simulation.step` decides it. ``project()``: the projection's iterations;
    sets params.projected = 1, params.projected_pairs and params.proj_worst. The same
    functions in the same order as the step launched kernel by kernel, so the same
    bits. Each function body appears once per kernel, and drift, grid build and
    detection stay top-level loops (separate tasks): Taichi compiles a loop nested in
    a ``while`` as part of one big serial function, and its compile time grows much
    faster than linearly with function size (a version with everything in one loop
    compiled 3-10x slower)."""

    def __init__(self, motion: Motion, grid: Grid, contacts: Contacts,
                 projection: Projection, real, solver_on: bool, tolerance: float):
        params = contacts.params

        @ti.kernel
        def step(h: real, max_sweeps: ti.i32, tol: ti.f64) -> ti.i32:
            params.h[None] = h
            motion._drift_body()
            grid._build_body()
            contacts._detect_all_body()
            sweeps = contacts.serial_sweeps(max_sweeps)
            far = contacts.status() % 2
            overlap = params.sep_overlap[None]
            if params.remaining[None] > 0:
                overlap = ti.max(overlap, params.open_overlap[None])
            due = 0
            # compared in f64, as the Python step compares its float copies (same bits)
            if ti.cast(overlap, ti.f64) > tol and \
                    params.remaining[None] > 0 and ti.static(not solver_on):
                due = 1
            return 4 * sweeps + 2 * far + due

        @ti.kernel
        def project(tol: ti.f64):
            params.projected[None] = 1
            grid._build_body()
            projection._project_all_body()
            it = 1
            while ti.cast(projection.worst[None], ti.f64) > tol:
                params.projected_pairs[None] += projection.pushed[None]
                if it == ti.static(projection.max_iterations):
                    break
                grid._build_body()
                projection._project_near_body()
                it += 1
            projection._finish_body()
            params.proj_worst[None] = projection.worst[None]

        # the tolerance goes in as an f64 argument: compared exactly as the Python step
        # compares its float copies, in f32 builds too
        self._step = step
        self._tolerance = tolerance
        self.project = lambda: project(tolerance)

    def step(self, h: float, max_sweeps: int) -> FusedOutcome:
        """One fused step of length h [s] with at most max_sweeps sweeps (the kernel
        returns 4 x sweeps + 2 x rebuild + project in one i32: one launch)."""
        status = self._step(h, max_sweeps, self._tolerance)
        return FusedOutcome(status >> 2, bool(status & 2), bool(status & 1))
