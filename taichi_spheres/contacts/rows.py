"""Contact rows of the contact solver (contacts/solver.py): which pairs and walls get
a row, in which order each owner cell sweeps them, and their geometry, targets and
warm-start impulses.

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti

from ..grid import FORWARD_ROWS
from .friction import clamped, rolling_bounded, tangential_part
from .friction_rows import GEOMETRY_ROWS


#: what ContactRows.record does with a row: count it for its owner cell; place it in
#: the cell's range (after the scan); or count it and keep it in the staging list
#: (serial gathering: the rows are then placed from the list, not found again)
COUNT, PLACE, STAGE = 0, 1, 2


class ContactRows:
    """Gathering rows per owner cell (count, scan, place, sort), their geometry and
    the warm start."""

    @ti.func
    def record(self, owner, a, b, how: ti.template()):
        """Row (a, b) of cell ``owner``: counted (COUNT), written in the cell's range
        (PLACE), or counted and staged (STAGE: ``staged``, in the order found)."""
        if ti.static(how == PLACE):
            slot = self.cell_start[owner] + ti.atomic_add(self.cell_fill[owner], 1)
            if slot < ti.static(self.capacity):
                self.row_a[slot] = a
                self.row_b[slot] = b
        else:
            ti.atomic_add(self.cell_count[owner], 1)
            if ti.static(how == STAGE):
                t = self.n_staged[None]
                self.n_staged[None] = t + 1
                if t < ti.static(self.capacity):
                    self.staged[t] = ti.Vector([owner, a, b])

    @ti.func
    def consider_pair(self, i, xi, vi, ri, q, ci, how: ti.template()):
        """Row for pair (i, j = grid.order[q]) if closer than the margin and not an
        impact to come (approaching at or above the pair's impact speed while still
        apart: walls.Motion.pair_impact_speed)."""
        j = self.grid.order[q]
        d = self.pairs.min_image(xi - self.grid.xs[q])
        sigma = ri + self.state.rad(j)
        reach = sigma + self.margin[None]
        dd = d.norm_sqr()
        if dd < reach * reach and dd > 0:
            dist = ti.sqrt(dd)
            un = (vi - self.state.v[j]).dot(d) / dist
            # with substeps an impact to come gets a row too, for the position pass only
            # (prepare_rows: inert_impact_row)
            if ti.static(self.rules.substeps) or dist < sigma or \
                    un >= -self.pairs.motion.pair_impact_speed(i, j):
                cj = self.grid.coords(self.grid.cell_of[j])
                owner = self.grid.linear(self.grid.owner(ci, cj))
                self.record(owner, ti.min(i, j), ti.max(i, j), how)
            else:               # its overlaps after the solve: overlaps.py
                self.unrowed[i] = 1
                self.unrowed[j] = 1

    @ti.func
    def consider_walls(self, i, xi, vi, ri, k, how: ti.template()):
        """Rows for sphere i (cell k) and the walls closer than the margin, unless it
        moves into one at or above that wall's impact speed (walls.Motion
        .wall_impact_speed: 0 for side walls and ceilings under gravity)."""
        for a in ti.static(range(3)):
            if ti.static(self.f.wall_axes[a]):
                g_a = ti.cast(0, self.real)
                if ti.static(self.f.gravity_axes[a]):
                    g_a = self.params.gravity[None][a]
                lo_gap = xi[a] - self.params.lo[None][a] - ri
                hi_gap = self.params.hi[None][a] - xi[a] - ri
                lo_imp = self.pairs.motion.wall_impact_speed(i, g_a)
                hi_imp = self.pairs.motion.wall_impact_speed(i, -g_a)
                # with substeps impacts to come get rows too (inert_impact_row)
                sub = ti.static(self.rules.substeps)
                if lo_gap < self.margin[None]:
                    if sub or lo_gap < 0 or -vi[a] <= lo_imp:
                        self.record(k, i, -1 - 2 * a, how)
                    else:       # its overlap after the solve: overlaps.py
                        self.unrowed[i] = 1
                if hi_gap < self.margin[None]:
                    if sub or hi_gap < 0 or vi[a] <= hi_imp:
                        self.record(k, i, -2 - 2 * a, how)
                    else:
                        self.unrowed[i] = 1

    @ti.func
    def consider_geometry(self, i, xi, vi, ri, k, how: ti.template()):
        """Rows for sphere i (cell k) and the geometry objects closer than the margin,
        unless it moves into one at or above the impact speed (surfaces.py)."""
        motion = self.pairs.motion
        for g in range(self.params.n_geo[None]):
            gap, n = motion.surface_gap(g, xi, ri)
            if gap < self.margin[None]:
                acc = ti.cast(0, self.real)
                if ti.static(self.f.gravity):
                    acc = self.params.gravity[None].dot(n)
                if ti.static(self.rules.substeps) or gap < 0 or \
                        -vi.dot(n) <= motion.wall_impact_speed(i, acc):
                    self.record(k, i, -1 - GEOMETRY_ROWS - g, how)
                else:           # its overlap after the solve: overlaps.py
                    self.unrowed[i] = 1

    @ti.func
    def gather_sphere(self, p, how: ti.template()):
        """Rows of the sphere at grid slot p: forward neighbours (grid.FORWARD_ROWS, each
        pair once) and walls."""
        i = self.grid.order[p]
        k = self.grid.cell_of[i]
        ci = self.grid.coords(k)
        xi = self.grid.xs[p]
        vi = self.state.v[i]
        ri = self.state.rad(i)
        for row in range(ti.static(len(FORWARD_ROWS))):
            a0, b0, a1, b1 = self.grid.row_ranges(ci, self.pairs.fwd_rows[row])
            if row == 0:
                a0 = p + 1
            for q in range(a0, b0):
                self.consider_pair(i, xi, vi, ri, q, ci, how)
            for q in range(a1, b1):
                self.consider_pair(i, xi, vi, ri, q, ci, how)
        if ti.static(self.f.walls):
            self.consider_walls(i, xi, vi, ri, k, how)
        if ti.static(self.f.geometry):
            self.consider_geometry(i, xi, vi, ri, k, how)

    @ti.func
    def row_before(self, s, t):
        """Row s comes before row t in a cell's sweep: pairs by (a, b), then wall rows
        by (a, wall)."""
        ws = self.row_b[s] < 0
        wt = self.row_b[t] < 0
        out = ws == False and wt == True  # noqa: E712 (Taichi expressions)
        if ws == wt:
            bs = self.row_b[s]
            bt = self.row_b[t]
            if ws:
                bs = -bs
                bt = -bt
            out = self.row_a[s] < self.row_a[t] or (self.row_a[s] == self.row_a[t] and bs < bt)
        return out

    @ti.func
    def sort_cell(self, k):
        """Insertion sort of cell k's rows into row_before order (a few rows)."""
        lo = self.cell_start[k]
        for s in range(lo + 1, self.cell_start[k + 1]):
            t = s
            while t > lo:     # (Taichi's `and` does not short-circuit: test t first)
                if not self.row_before(t, t - 1):
                    break
                a = self.row_a[t]
                b = self.row_b[t]
                self.row_a[t] = self.row_a[t - 1]
                self.row_b[t] = self.row_b[t - 1]
                self.row_a[t - 1] = a
                self.row_b[t - 1] = b
                t -= 1

    @ti.func
    def scan_cells(self):
        """cell_start = exclusive prefix sum of cell_count; n_rows (the grid's blocked
        scan, Grid.exclusive_scan)."""
        m = self.grid.n_cells[None]
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(m):
            self.cell_start[k] = self.cell_count[k]
        self.grid.exclusive_scan(self.scan_bufs)
        total = self.cell_start[m - 1] + self.cell_count[m - 1]
        self.cell_start[m] = total
        self.n_rows[None] = total

    @ti.func
    def gather(self):
        """Count, place and sort the rows of the bound grid (kernel top level). In
        parallel the spheres' neighbours are searched twice, to count the rows per owner
        cell and to place them after the scan; serially once, the rows staged in the
        order found and placed from that list (the same order as a second search)."""
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.grid.n_cells[None]):
            self.cell_count[k] = 0
            self.cell_fill[k] = 0
        if ti.static(self.serial):
            self.n_staged[None] = 0
            ti.loop_config(serialize=True)
            for p in range(self.state.n_spheres[None]):
                self.gather_sphere(p, STAGE)
            self.scan_cells()
            ti.loop_config(serialize=True)
            for t in range(ti.min(self.n_staged[None], ti.static(self.capacity))):
                row = self.staged[t]
                self.record(row[0], row[1], row[2], PLACE)
        else:
            for p in range(self.state.n_spheres[None]):
                self.gather_sphere(p, COUNT)
            self.scan_cells()
            for p in range(self.state.n_spheres[None]):
                self.gather_sphere(p, PLACE)
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.grid.n_cells[None]):
            self.sort_cell(k)

    @ti.func
    def row_geometry(self, s):
        """(normal, gap [m], effective mass [kg]) of row s at the current positions."""
        a = self.row_a[s]
        b = self.row_b[s]
        n = ti.Vector.zero(self.real, 3)
        gap = ti.cast(0, self.real)
        meff = 1 / self.inv_mass(a)
        if b >= 0:
            d = self.pairs.min_image(self.state.x[a] - self.state.x[b])
            dist = d.norm()
            n[2] = 1       # centres that met (a pair crushed into one point): a fixed axis
            if dist > 0:
                n = d / dist
            gap = dist - self.state.rad(a) - self.state.rad(b)
            meff = 1 / (self.inv_mass(a) + self.inv_mass(b))
        else:
            wall = -1 - b
            r = self.state.rad(a)
            if wall < GEOMETRY_ROWS:
                side = wall % 2
                for ax in ti.static(range(3)):
                    if ti.static(self.f.wall_axes[ax]):
                        if wall // 2 == ax:
                            if side == 0:
                                n[ax] = 1
                                gap = self.state.x[a][ax] - self.params.lo[None][ax] - r
                            else:
                                n[ax] = -1
                                gap = self.params.hi[None][ax] - self.state.x[a][ax] - r
            # (scenes without objects have no object rows: their code is compiled out)
            if ti.static(self.f.geometry):
                if wall >= GEOMETRY_ROWS:
                    gap, n = self.pairs.motion.surface_gap(wall - GEOMETRY_ROWS,
                                                           self.state.x[a], r)
        return n, gap, meff

    @ti.func
    def has_last_step(self):
        """True when a solved step came before this one (h_prev > 0: the warm-start
        table holds its impulses); a new Simulation's first solve is cold."""
        return self.h_prev[None] > 0

    @ti.func
    def warm_slot(self, a, b):
        """The slot of row (a, b) in sphere a's warm-start table, or -1 if it is new."""
        out = -1
        kept = self.warm_n[a]
        if kept <= ti.static(self.perf.warm_slots) and self.has_last_step():
            for t in range(kept):
                if self.warm_key[a, t] == b:
                    out = t
        return out

    @ti.func
    def warm_row(self, s):
        """Start row s from last step's impulses of the same contact, scaled by h /
        h_prev (normal; with friction the tangential impulse turned into the new tangent
        plane and within the friction cone, the rolling one within its bound)."""
        a = self.row_a[s]
        t = self.warm_slot(a, self.row_b[s])
        if t >= 0:
            scale = self.params.h[None] / self.h_prev[None]
            self.lam[s] = self.warm_lam[a, t] * scale
            if ti.static(self.f.friction):
                n = self.normal[s]
                self.lam_t[s] = clamped(tangential_part(self.warm_t[a, t], n) * scale,
                                        self.row_friction(s) * self.lam[s])
                if ti.static(self.f.rolling):
                    self.lam_r[s] = rolling_bounded(self.warm_r[a, t] * scale, n,
                                                    self.rolling_limit(s))

    @ti.func
    def inert_impact_row(self, s, n, gap):
        """With Rules.substeps, rows are also gathered for impacts to come (a pair, wall
        or object apart, approached at or above its impact speed: the impact pass
        collides them exactly). Their velocity row is made inert (target -inf, no
        impulse), so only the position pass sees them: where the solve's position
        update (the trapezoidal move) pushes a sphere it stopped into such a
        neighbour or wall, which the longer steps of substeps make deep enough to
        matter. An approach that closes at most the position tolerance in the step
        (delta / h, a tenth of Rules.overlap_tolerance of the smallest diameter per
        step) is no impact to come, whatever the pair's impact speed: two spheres
        resting on each other without load flags (a new Simulation's first step)
        approach by round-off, and with an inert row the lower one was stopped while
        the upper one kept falling, its overlap pushed out by the position pass but
        its speed kept: energy from nothing (a settled block, ~(g h)^2 / 2 per
        sphere)."""
        a = self.row_a[s]
        b = self.row_b[s]
        if gap > 0:
            un = self.state.v[a].dot(n)
            impact = ti.cast(0, self.real)
            if b >= 0:
                un -= self.state.v[b].dot(n)
                impact = self.pairs.motion.pair_impact_speed(a, b)
            else:
                acc = ti.cast(0, self.real)
                if ti.static(self.f.gravity):
                    acc = self.params.gravity[None].dot(n)
                impact = self.pairs.motion.wall_impact_speed(a, acc)
            if un < -ti.max(impact, self.tol_len[None] / self.params.h[None]):
                self.target[s] = -ti.cast(1e30, self.real)
                self.lam[s] = 0
                if ti.static(self.f.friction):
                    self.lam_t[s] = ti.Vector.zero(self.real, 3)
                if ti.static(self.f.rolling):
                    self.lam_r[s] = ti.Vector.zero(self.real, 3)

    @ti.func
    def prepare_rows(self):
        """Geometry, targets and warm impulses of every row; v_pre (kernel top level)."""
        h = self.params.h[None]
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(ti.min(self.n_rows[None], ti.static(self.capacity))):
            n, gap, meff = self.row_geometry(s)
            self.normal[s] = n
            self.gap[s] = gap
            self.meff[s] = meff
            # gaps within the position tolerance count as touching (no target noise)
            self.target[s] = -ti.max(gap - self.tol_len[None], 0) / h
            self.lam[s] = 0
            if ti.static(self.f.friction):
                self.lam_t[s] = ti.Vector.zero(self.real, 3)
                self.keep_row_coefficients(s)
            if ti.static(self.f.rolling):
                self.lam_r[s] = ti.Vector.zero(self.real, 3)
            if ti.static(self.rules.warm_start):
                self.warm_row(s)
            if ti.static(self.rules.substeps):
                self.inert_impact_row(s, n, gap)
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(self.state.n_spheres[None]):
            self.v_pre[i] = self.state.v[i]
            self.x_pre[i] = self.state.x[i]
            self.w[i] = ti.Vector.zero(self.real, 3)
            if ti.static(self.f.friction):
                self.w_pre[i] = self.state.omega[i]
