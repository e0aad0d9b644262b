"""Overlap projection (step stage 4b): the safety net of resting contact and dense impacts.

The sweeps of :mod:`taichi_spheres.contacts` resolve approaching overlaps by rewinding
them to contact. In dense piles hit by a stream, or when the sweep limit is reached,
some overlaps can remain; left alone they would deepen step after step until spheres
pass through each other. After the sweeps of a step that hit the sweep limit, or of
any step in a scene with resting contact (gravity and the rest rule), every pair that overlaps by more than
``tolerance`` x its contact distance is pushed apart along its line of centres
(Jacobi iterations, so that no two threads write one sphere; relaxation 1/2, at most
``max_iterations`` per step). Each pair's push is split by inverse mass
(``dx_i = w_i d n``, ``dx_j = -w_j d n``), so the centre of mass of the pair does not
move and the potential energy in uniform gravity does not change; velocities are not
touched (an approaching pair is collided by the next step's sweeps). A sphere pushed
past a wall is then put back by the walls' energy-safe placement
(:meth:`taichi_spheres.walls.Motion.walls_and_wrap`).
"""

import taichi as ti

from .contacts import Contacts
from .grid import ALL_ROWS, Grid
from .state import Features, SphereState
from .walls import Motion

#: Pairs overlapping by more than this fraction of their contact distance are projected.
DEFAULT_TOLERANCE = 1e-4
#: Jacobi iterations per step at most (each one scans the neighbourhood of every sphere).
MAX_ITERATIONS = 8
#: Jacobi relaxation: each iteration removes this fraction of every pair's overlap.
RELAXATION = 0.5


@ti.data_oriented
class Projection:
    """Fields: push (N,) vec3 real — displacement of each sphere in this iteration [m];
    worst (0-d) real — largest relative overlap seen by the last iteration (before its
    push); pushed (0-d) i32 — pairs pushed by the last iteration."""

    def __init__(self, state: SphereState, grid: Grid, contacts: Contacts, motion: Motion,
                 features: Features, serial: bool, tolerance: float):
        self.state = state
        self.grid = grid
        self.contacts = contacts    # its minimum-image separation and stencil table
        self.motion = motion
        self.f = features
        self.real = state.real
        self.n = state.n
        self.serial = serial
        self.tolerance = tolerance
        self.push = ti.Vector.field(3, self.real, shape=self.n)
        self.worst = ti.field(self.real, shape=())
        self.pushed = ti.field(ti.i32, shape=())

        @ti.kernel
        def project_once():
            self._project_body()

        self.project_once = project_once

    @ti.func
    def _project_body(self):
        """One Jacobi iteration: measure every overlap, push pairs above tolerance apart
        by RELAXATION x their overlap, then put spheres back inside the box."""
        self.worst[None] = 0
        self.pushed[None] = 0
        tol = ti.cast(ti.static(self.tolerance), self.real)
        ti.loop_config(serialize=ti.static(self.serial))
        for p in range(self.n):
            i = self.grid.order[p]
            ci = self.grid.coords(self.grid.cell_of[i])
            xi = self.state.x[i]
            acc = ti.Vector.zero(self.real, 3)
            wi_num = ti.cast(1, self.real)
            if ti.static(not self.f.equal_masses):
                wi_num = self.state.inv_mass_of(i)
            for k in range(ti.static(len(ALL_ROWS))):
                a0, b0, a1, b1 = self.grid.row_ranges(ci, self.contacts.all_rows[k])
                for q in range(a0, b0):
                    acc += self.pair_push(xi, i, self.grid.order[q], wi_num, tol)
                for q in range(a1, b1):
                    acc += self.pair_push(xi, i, self.grid.order[q], wi_num, tol)
            self.push[i] = acc
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.n):
            dx = self.push[i]
            if dx.norm_sqr() > 0:
                self.state.x[i] += dx
                self.motion.walls_and_wrap(i)

    @ti.func
    def pair_push(self, xi, i, j, wi_num, tol):
        """Displacement of sphere i [m] from its overlap with j (zero below tolerance):
        RELAXATION x overlap along the line of centres, times i's inverse-mass weight."""
        out = ti.Vector.zero(self.real, 3)
        if j != i:
            d, sigma = self.contacts.separation_from(xi, i, j)
            dd = d.norm_sqr()
            if dd < sigma * sigma:
                dist = ti.sqrt(dd)
                rel = 1 - dist / sigma
                ti.atomic_max(self.worst[None], rel)
                if rel > tol and dist > 0:
                    w = ti.cast(0.5, self.real)
                    if ti.static(not self.f.equal_masses):
                        w = wi_num / (wi_num + self.state.inv_mass_of(j))
                    out = ti.cast(RELAXATION, self.real) * w * (sigma - dist) / dist * d
                    if i < j:
                        ti.atomic_add(self.pushed[None], 1)
        return out
