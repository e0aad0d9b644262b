"""How one step runs (docs/design.md, "One step, in parallel"): the collision stages
behind one interface, then the contact solver and the projection.

:class:`KernelPath` launches drift, grid build, detection and each detect/resolve sweep
as kernels of their own; :class:`FusedPath` (small systems on the CPU) runs them as
one or two kernel launches (fused.py) and hands over to the kernel path when a sphere
moved past the grid's slack. Both return the sweeps they ran and give the same bits.
:class:`Stepper` runs a path, then the contact solver (contacts/solver.py) or, without
one, the overlap projection (projection.py), and reads the step's counters back.
"""
from __future__ import annotations

from .contacts import decode_status
from .params import merge_substeps

__all__ = ["KernelPath", "FusedPath", "Stepper"]


class KernelPath:
    """Drift, grid, detection and detect/resolve sweeps, kernel by kernel, over the
    engine of Simulation ``sim`` (counts grid rebuilds and near-list detections in its
    totals)."""

    fused = False

    def __init__(self, sim):
        self.engine = sim._engine
        self.totals = sim._totals

    def collide(self, h: float, max_sweeps: int) -> int:
        """One step's collision stages for a step of length h [s]; returns the sweeps."""
        self.engine.params.h[None] = h
        self.engine.motion.drift()
        self.engine.grid.build()
        return self.sweep(self.detect(), 0, max_sweeps)

    def sweep(self, remaining: int, sweeps: int, max_sweeps: int) -> int:
        """Detect/resolve sweeps while approaching overlaps remain (at most max_sweeps
        in all, ``sweeps`` of them already run); returns the sweeps run in all."""
        while remaining > 0 and sweeps < max_sweeps:
            found = decode_status(self.engine.contacts.sweep(remaining))
            remaining = found.remaining
            sweeps += 1
            if found.rebuild:
                remaining = self.rebuild()
        return sweeps

    def rebuild(self) -> int:
        """A sphere moved farther than the grid's margin since the grid was built, so the
        last re-detection may have missed a pair: re-bin and detect again; returns the
        approaching overlaps found."""
        self.engine.grid.build()
        self.totals["grid_rebuilds"] += 1
        return self.detect()

    def detect(self) -> int:
        """Full detection on a freshly built grid (from the near lists when they still
        cover); returns the approaching overlaps found."""
        status, from_list = self.engine.contacts.detect()
        self.totals["near_list_detections"] += int(from_list)
        return decode_status(status).remaining


class FusedPath(KernelPath):
    """The same stages in one or two kernel launches (fused.py)."""

    fused = True

    def __init__(self, sim):
        super().__init__(sim)
        self.kernel = self.engine.fused_step()

    def collide(self, h: float, max_sweeps: int) -> int:
        outcome = self.kernel.step(h, max_sweeps)
        if outcome.rebuild:
            # a sphere moved farther than the grid's margin: go on kernel by kernel
            return self.sweep(self.rebuild(), outcome.sweeps, max_sweeps)
        if outcome.project:
            self.kernel.project()
        return outcome.sweeps


class Stepper:
    """One step of Simulation ``sim``: its path (fused or kernel by kernel), then the
    contact solver or the projection."""

    def __init__(self, sim, fused: bool):
        self.sim = sim
        self.path = FusedPath(sim) if fused else KernelPath(sim)

    @property
    def fused(self) -> bool:
        return self.path.fused

    def step(self, h: float, max_sweeps: int, substep=None):
        """Run a step of length h [s]; returns (counters, sweeps, unresolved, overlap):
        params.read_back (with ``substeps``: how many drift/impact substeps ran), the
        sweeps, the approaching overlaps left, the largest relative overlap after the
        step. ``substep``: None, or (with a contact solver, Rules.substeps) a function
        giving the longest substep [s] for a largest squared speed [m^2/s^2]: drift
        and impacts then run in such substeps and the solver once, for all of h."""
        engine = self.sim._engine
        before, substeps = None, 1
        if substep is None:
            sweeps = last = self.path.collide(h, max_sweeps)
        else:
            sweeps, last, before, substeps, h = self.collide_in_substeps(h, max_sweeps, substep)
        if engine.solver is not None:
            if substep is not None:     # the solver's step (each substep set its own)
                engine.params.h[None] = h
            if last > 0:
                engine.grid.build()     # impacts moved spheres: bin them again
            engine.solver.solve()
        c = merge_substeps(before, engine.params.read_back())
        self.check_rows(c)
        remaining = int(c.remaining)
        overlap = float(c.contact_overlap if engine.solver is not None else c.sep_overlap)
        if remaining > 0:
            overlap = max(overlap, float(c.open_overlap))
        # projection only without a contact solver, for overlaps left at the sweep limit
        # (a gas's leftover overlaps separate by themselves); a fused step has done it
        tolerance = self.sim.overlap_tolerance
        if c.projected:
            overlap = float(c.proj_worst)
            self.sim._totals["projected_steps"] += 1
            self.sim._totals["projected_pairs"] += int(c.projected_pairs)
        elif overlap > tolerance and remaining > 0 and engine.solver is None:
            overlap = self.project()
            # the counters again: spheres the projection put back inside the box
            # count as wall events (and their energy), as in a fused step
            c = engine.params.read_back()
        c.substeps, c.length = substeps, h
        return c, sweeps, remaining, overlap

    def collide_in_substeps(self, h: float, max_sweeps: int, substep):
        """Drift and impacts over at most h [s] in substeps, each as long as ``substep``
        allows for the largest speed at its start, up to h or up to the end of the
        first substep in which a sphere that had a contact row collided (the solver
        then takes the spheres it set moving at once, as a step without substeps does;
        a sphere without one was farther than the rows' margin from every other, more
        than a sub-impact-speed approach closes in the step) or a sphere's centre
        entered a sink (so that it leaves before it can fall through; spheres a recycle
        sink kept for want of a free spot do not count); returns (sweeps in all,
        sweeps of the last substep, the counters of the substeps before the last
        merged or None, substeps, the time they span [s])."""
        params = self.sim._engine.params
        done, sweeps, before, count = 0.0, 0, None, 0
        vmax2 = self.sim._vmax2
        while True:
            left = h - done
            length = substep(vmax2)
            last = self.path.collide(left if length >= left else length, max_sweeps)
            sweeps += last
            count += 1
            if length >= left:
                return sweeps, last, before, count, h
            c = params.read_back()
            if c.near_hits > 0 or c.in_sinks > self.sim._stuck_in_sinks:
                return sweeps, last, before, count, done + length
            before = merge_substeps(before, c)
            vmax2 = float(c.vmax2)
            done += length

    def check_rows(self, c) -> None:
        """RuntimeError when the contact rows did not fit the solver's fields."""
        solver = self.sim._engine.solver
        if solver is not None and c.contacts > solver.capacity:
            raise RuntimeError(
                f"{c.contacts} contacts do not fit the contact solver's {solver.capacity} "
                f"rows: raise Tuning performance contacts_per_sphere (now "
                f"{self.sim.tuning.performance.contacts_per_sphere})")

    def project(self) -> float:
        """Push apart pairs overlapping beyond the tolerance (projection.py); returns
        the largest relative overlap the last iteration measured."""
        engine, totals = self.sim._engine, self.sim._totals
        proj = engine.projection
        for it in range(self.sim.tuning.physics.projection_iterations):
            engine.grid.build()
            (proj.project_near if it else proj.project_all)()
            if float(proj.worst[None]) <= self.sim.overlap_tolerance:
                break
            totals["projected_pairs"] += int(proj.pushed[None])
        proj.finish()
        totals["projected_steps"] += 1
        return float(proj.worst[None])
