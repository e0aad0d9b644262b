"""Overlap projection (step stage 4b): the safety net of dense impacts without a contact
solver.

The sweeps of :mod:`taichi_spheres.contacts` resolve approaching overlaps by rewinding
them to contact. When the sweep limit is reached some overlaps can remain; left alone
they could deepen step after step until spheres pass through each other. After the
sweeps of a step that hit the sweep limit, in a scene without a contact solver (with
one, its split impulse removes overlap: contacts/solver.py), every pair that overlaps by more than
``tolerance`` x its contact distance is pushed apart along its line of centres
(Jacobi iterations, so that no two threads write one sphere; relaxation 1/2, at most
``max_iterations`` per step). Each pair's push is split by inverse mass
(``dx_i = w_i d n``, ``dx_j = -w_j d n``), so the centre of mass of the pair does not
move and the potential energy in uniform gravity does not change; velocities are not
touched (an approaching pair is collided by the next step's sweeps). A sphere pushed
past a wall is then put back by the walls' energy-safe placement
(:meth:`taichi_spheres.walls.Motion.walls_and_wrap`).

Only the first iteration scans every sphere. A pair's overlap changes only if one of
its spheres moved, and only spheres in a pair above tolerance (*involved*) move, so a
later iteration examines just the spheres within the 27-cell stencil of the spheres
involved in the iteration before: every other pair is unchanged and below tolerance.
Each examined sphere's push is computed over all its pairs as in a full scan, so the
positions are the same bits as with a full scan every iteration
(``Performance.projection_near_sets = False``, tests), and so are the pushed-pair counts and the largest overlap, which is kept per
sphere (``rmax``) and reduced over all spheres once at the end.
"""

import taichi as ti

from .config import DEFAULT, Tuning
from .contacts import Contacts
from .grid import ALL_ROWS, Grid
from .state import Features, SphereState
from .walls import Motion



@ti.data_oriented
class Projection:
    """Fields: push (N,) vec3 real — displacement of each sphere in this iteration [m];
    rmax (N,) real — largest relative overlap of each sphere's pairs when it was last
    examined (exact for every sphere, see the module docstring); involved (N,) /
    n_involved — spheres with a pair above tolerance in the last iteration; near (N,) /
    n_near — the spheres the next iteration examines, marked by ``stamp`` (N,) i32 =
    the iteration that listed them (iterations count from 1: 0, as allocated, lists
    none); worst (0-d) real — largest relative overlap the
    last iteration measured (before its push) among the pairs it examined, or over all
    spheres after ``finish``; pushed (0-d) i32 — pairs pushed by the last iteration."""

    def __init__(self, state: SphereState, grid: Grid, contacts: Contacts, motion: Motion,
                 features: Features, serial: bool, tuning: Tuning = DEFAULT):
        self.state = state
        self.grid = grid
        self.contacts = contacts    # its minimum-image separation
        self.motion = motion
        self.f = features
        self.real = state.real
        self.serial = serial
        # relative overlap above which pairs are pushed, iterations per step at most,
        # fraction of an overlap one iteration removes, near sets (config.py)
        self.tolerance = tuning.physics.overlap_tolerance
        self.max_iterations = tuning.physics.projection_iterations
        self.relaxation = tuning.physics.projection_relaxation
        self.near_sets = tuning.performance.projection_near_sets
        cap = state.capacity
        self.push = ti.Vector.field(3, self.real, shape=cap)
        self.rmax = ti.field(self.real, shape=cap)
        self.involved = ti.field(ti.i32, shape=cap)
        self.n_involved = ti.field(ti.i32, shape=())
        self.near = ti.field(ti.i32, shape=cap)
        self.n_near = ti.field(ti.i32, shape=())
        self.stamp = ti.field(ti.i32, shape=cap)
        self.iteration = ti.field(ti.i32, shape=())
        self.worst = ti.field(self.real, shape=())
        self.pushed = ti.field(ti.i32, shape=())

        @ti.kernel
        def project_all():
            self._project_all_body()

        @ti.kernel
        def project_near():
            self._project_near_body()

        @ti.kernel
        def finish():
            self._finish_body()

        self.project_all = project_all
        self.project_near = project_near
        self.finish = finish

    @ti.func
    def _project_all_body(self):
        """First iteration: measure every overlap, push pairs above tolerance apart by
        the relaxation x their overlap, then put spheres back inside the box."""
        self._begin_iteration()
        ti.loop_config(serialize=ti.static(self.serial))
        for p in range(self.state.n_spheres[None]):
            self.examine(self.grid.order[p])
        self._apply()

    @ti.func
    def _project_near_body(self):
        """A later iteration: the same for the spheres near those involved before."""
        if ti.static(self.near_sets):
            self.iteration[None] += 1
            self.n_near[None] = 0
            ti.loop_config(serialize=ti.static(self.serial))
            for t in range(self.n_involved[None]):
                self.list_around(self.involved[t])
            self._begin_iteration()
            ti.loop_config(serialize=ti.static(self.serial))
            for t in range(self.n_near[None]):
                self.examine(self.near[t])
            self._apply()
        else:
            self._project_all_body()

    @ti.func
    def _finish_body(self):
        """worst = the largest relative overlap over all spheres (after the last
        iteration: the same value as a full scan would have measured in it)."""
        self.worst[None] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            ti.atomic_max(self.worst[None], self.rmax[i])

    @ti.func
    def _begin_iteration(self):
        self.worst[None] = 0
        self.pushed[None] = 0
        self.n_involved[None] = 0

    @ti.func
    def _apply(self):
        """Move the involved spheres by their push and put them back inside the box."""
        ti.loop_config(serialize=ti.static(self.serial))
        for t in range(self.n_involved[None]):
            i = self.involved[t]
            dx = self.push[i]
            if dx.norm_sqr() > 0:
                self.state.x[i] += dx
                self.motion.contain(i)

    @ti.func
    def list_around(self, i):
        """Add every sphere of the 27 cells around sphere i (i included) to ``near``,
        once per iteration."""
        ci = self.grid.coords(self.grid.cell_of[i])
        it = self.iteration[None]
        for k in range(ti.static(len(ALL_ROWS))):
            a0, b0, a1, b1 = self.grid.row_ranges(ci, self.grid.all_rows[k])
            for q in range(a0, b0):
                self.list_once(self.grid.order[q], it)
            for q in range(a1, b1):
                self.list_once(self.grid.order[q], it)

    @ti.func
    def list_once(self, j, it):
        if ti.atomic_max(self.stamp[j], it) < it:
            self.near[ti.atomic_add(self.n_near[None], 1)] = j

    @ti.func
    def examine(self, i):
        """push[i] and rmax[i] from all pairs of sphere i; list i as involved if one of
        its pairs is above tolerance."""
        tol = ti.cast(ti.static(self.tolerance), self.real)
        ci = self.grid.coords(self.grid.cell_of[i])
        xi = self.state.x[i]
        acc = ti.Vector.zero(self.real, 3)
        worst = ti.cast(0, self.real)
        wi_num = ti.cast(1, self.real)
        if ti.static(not self.f.equal_masses):
            wi_num = self.state.inv_mass_of(i)
        for k in range(ti.static(len(ALL_ROWS))):
            a0, b0, a1, b1 = self.grid.row_ranges(ci, self.grid.all_rows[k])
            for q in range(a0, b0):
                dx, rel = self.pair_push(xi, i, q, wi_num, tol)
                acc += dx
                worst = ti.max(worst, rel)
            for q in range(a1, b1):
                dx, rel = self.pair_push(xi, i, q, wi_num, tol)
                acc += dx
                worst = ti.max(worst, rel)
        self.push[i] = acc
        self.rmax[i] = worst
        ti.atomic_max(self.worst[None], worst)
        if worst > tol:
            self.involved[ti.atomic_add(self.n_involved[None], 1)] = i

    @ti.func
    def pair_push(self, xi, i, q, wi_num, tol):
        """(displacement of sphere i [m] from its overlap with j = grid.order[q], zero
        below tolerance: the relaxation x overlap along the line of centres, times i's
        inverse-mass weight; relative overlap 1 - |d|/sigma, 0 if they do not overlap).
        x_j comes from grid.xs: every iteration examines right after a grid build."""
        out = ti.Vector.zero(self.real, 3)
        rel = ti.cast(0, self.real)
        j = self.grid.order[q]
        if j != i:
            d, sigma = self.contacts.separation_between(xi, self.grid.xs[q], i, j)
            dd = d.norm_sqr()
            if dd < sigma * sigma:
                dist = ti.sqrt(dd)
                rel = 1 - dist / sigma
                if rel > tol and dist > 0:
                    w = ti.cast(0.5, self.real)
                    if ti.static(not self.f.equal_masses):
                        w = wi_num / (wi_num + self.state.inv_mass_of(j))
                    out = ti.cast(ti.static(self.relaxation), self.real) * w * (sigma - dist) / dist * d
                    if i < j:
                        ti.atomic_add(self.pushed[None], 1)
        return out, rel
