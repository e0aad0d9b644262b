"""Near lists: a full scan keeps each sphere's forward neighbours closer than the
narrowest cell; later detections examine only those pairs, plus every neighbour of the
spheres that moved more than the allowance since (scanned around in the grid), until
too many have (same pairs and bits as the scan).

A mixin of :class:`taichi_spheres.contacts.Contacts` (its fields and options).
"""

import taichi as ti

from ..config import DEFAULT


def near_allowance(geom, r_max, safety=DEFAULT.performance.near_safety):
    """(reach, allowance) of near lists on grid ``geom`` with largest radius r_max [m]:
    a full scan visits every pair closer than ``reach`` (the narrowest cell; an axis
    of at most 2 cells without wrap has every pair adjacent), so a list of those pairs
    still holds every pair that can overlap while no sphere has moved more than
    ``allowance`` = (reach - 2 r_max)/2 x safety (Performance.near_safety) since the
    list was made (two spheres close in by at most twice that). allowance <= 0: lists
    are of no use."""
    reach = min((c for c, d, per in zip(geom.cell, geom.dims, geom.periodic)
                 if per or d > 2), default=float("inf"))
    if reach == float("inf"):
        return reach, 0.0
    return reach, safety * 0.5 * (reach - 2.0 * r_max)


class NearLists:
    """Keeping near lists during a full scan and detecting from them."""

    @ti.func
    def keep_near(self, p, q, dd, kept):
        """Append j = grid.order[q] to the near list of the sphere at slot p if closer
        than near_reach (dd = squared distance [m^2]); returns the new count (past
        near_capacity: the list is incomplete, the pair is not stored)."""
        out = kept
        if dd < self.near_reach2[None]:
            if kept < ti.static(self.perf.near_capacity):
                self.near[p, kept] = self.grid.order[q]
            out += 1
        return out

    @ti.func
    def mark_fast_movers(self):
        """Mark (as touched) every sphere that moved farther than the allowance
        (minimum image) since its near list was made (call at kernel top level)."""
        ti.loop_config(serialize=ti.static(self.serial_light))
        for k in range(self.state.n_spheres[None]):
            i = self.near_id[k]
            d = self.min_image(self.state.x[i] - self.x_near[k])
            if d.norm_sqr() > self.near_allowance2[None]:
                self.mark_touched(i)

    @ti.func
    def near_live(self):
        """The near lists can serve this detection (after mark_fast_movers): complete
        when made, and few enough fast movers to scan around."""
        return self.near_ok[None] == 1 and \
            self.n_touched[None] <= self.state.n_spheres[None] // ti.static(self.perf.near_fast_limit)

    @ti.func
    def scan_near(self, live):
        """The full detection from the near lists, when live (call at kernel top
        level). Every pair of two spheres that moved less than the allowance is
        listed; a listed pair that overlaps is examined once (same counts and bits as
        scan_forward), unless one of its spheres is marked as a fast mover: those are
        examined against every neighbour afterwards (detect_around_touched)."""
        n = 0
        if live:
            n = self.state.n_spheres[None]
        ti.loop_config(serialize=ti.static(self.serial_heavy))
        for k in range(n):
            i = self.near_id[k]
            xi = self.state.x[i]
            for t in range(self.n_near[k]):
                j = self.near[k, t]
                xj = self.state.x[j]
                d, sigma = self.separation_between(xi, xj, i, j)
                if d.norm_sqr() < sigma * sigma:
                    q = self.grid.slot[j]
                    if self.marked[self.grid.slot[i]] == 0 and self.marked[q] == 0:
                        self.examine(xi, i, q, self.grid.coords(self.grid.cell_of[i]), False, False)
