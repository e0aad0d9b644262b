"""The largest overlap after a solve, where the solver's rows do not reach.

The solver's rows cover the pairs and walls it solves and measure their overlaps; an
impact to come (apart and approaching at or above the impact speed at the start of
the step) has none. The solve's position update (the trapezoidal move) can push a
sphere it stopped into such a neighbour or wall, and that overlap would be neither
removed in the step nor seen on the rows (docs/algorithm.md, "What is counted").
Gathering the rows flags the spheres of such impacts to come (``unrowed``, rows.py);
after the solve this pass measures every pair (the full stencil) and every wall and
object of a flagged sphere at the positions the step ends with, and clears the flag.
It only measures: positions and velocities are not touched, so it changes no
trajectory. In a bed nothing is flagged and the pass reads one flag per sphere. With
Rules.substeps it does not run: every impact to come has a position-only row there
(rows.py ``inert_impact_row``), measured on the rows.

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti

from ..grid import ALL_ROWS


class OverlapMeasure:
    """params.contact_overlap over the pairs, walls and objects of the spheres with an
    impact to come and no row for it."""

    @ti.func
    def pair_overlap(self, i, xi, q):
        """Relative overlap (1 - distance / contact distance; <= 0: apart) of sphere i
        at xi and j = grid.order[q] at its current position."""
        j = self.grid.order[q]
        d = self.pairs.min_image(xi - self.state.x[j])
        sigma = self.state.rad(i) + self.state.rad(j)
        rel = ti.cast(0, self.real)
        dd = d.norm_sqr()
        if dd < sigma * sigma and j != i:
            rel = 1 - ti.sqrt(dd) / sigma
        return rel

    @ti.func
    def boundary_overlap(self, i, xi):
        """Largest relative overlap (gap / diameter, negated) of sphere i at xi with the
        box's walls and the geometry objects; 0 where it touches none."""
        ri = self.state.rad(i)
        worst = ti.cast(0, self.real)
        for a in ti.static(range(3)):
            if ti.static(self.f.wall_axes[a]):
                worst = ti.max(worst, -(xi[a] - self.params.lo[None][a] - ri) / (2 * ri))
                worst = ti.max(worst, -(self.params.hi[None][a] - xi[a] - ri) / (2 * ri))
        if ti.static(self.f.geometry):
            for g in range(self.params.n_geo[None]):
                gap, _ = self.pairs.motion.surface_gap(g, xi, ri)
                worst = ti.max(worst, -gap / (2 * ri))
        return worst

    @ti.func
    def measure_overlaps(self):
        """params.contact_overlap = max(itself, the largest relative overlap of the
        flagged spheres (``unrowed``) with every sphere of their full stencil
        (grid.ALL_ROWS) and every wall and object), at the current positions; clears
        the flags (kernel top level, after the solve moved the spheres). The grid was
        built this step; the solve's moves stay within its slack."""
        ti.loop_config(serialize=ti.static(self.serial))
        for p in range(self.state.n_spheres[None]):
            i = self.grid.order[p]
            if self.unrowed[i] != 0:
                self.unrowed[i] = 0
                ci = self.grid.coords(self.grid.cell_of[i])
                xi = self.state.x[i]
                worst = ti.cast(0, self.real)
                if ti.static(self.f.walls or self.f.geometry):
                    worst = self.boundary_overlap(i, xi)
                for row in range(ti.static(len(ALL_ROWS))):
                    a0, b0, a1, b1 = self.grid.row_ranges(ci, self.grid.all_rows[row])
                    for q in range(a0, b0):
                        worst = ti.max(worst, self.pair_overlap(i, xi, q))
                    for q in range(a1, b1):
                        worst = ti.max(worst, self.pair_overlap(i, xi, q))
                if worst > 0:
                    ti.atomic_max(self.params.contact_overlap[None], worst)
