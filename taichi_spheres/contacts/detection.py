"""Detection: find the overlapping pairs to resolve, on a freshly built grid or around
the spheres a sweep moved, and count them for their owner cells.

A mixin of :class:`taichi_spheres.contacts.Contacts` (its fields and options).
"""

import taichi as ti

from ..grid import FORWARD_ROWS


class Detection:
    """The half-stencil scan of every sphere, the walks around touched spheres, and
    the detection status."""

    @ti.func
    def status(self):
        """2 x params.remaining (approaching overlaps found by the last detection) + 1
        if a sphere moved farther than the grid's slack since the grid was built (the
        grid must be rebuilt before the next sweep). Decode with :func:`decode_status`."""
        far = 0
        if self.params.moved[None] > self.grid.slack[None]:
            far = 1
        return 2 * self.params.remaining[None] + far

    @ti.func
    def examine(self, xi, i, q, ci, record: ti.template(), only_new: ti.template()):
        """Classify pair (i, j = grid.order[q]), i at xi in cell ci (vec3): an overlap to
        resolve (see contact_time) is counted for its owner cell; any other overlap only
        updates the max overlap. record=True (tests): only append the pairs to resolve to
        a list. only_new (re-detection after a sweep): skip j = i, and a pair of two
        touched spheres from the higher id (it is examined from the lower one).
        Returns |x_i - x_j|^2 [m^2]."""
        j = self.grid.order[q]
        d, sigma = self.separation_between(xi, self.grid.xs[q], i, j)
        dd = d.norm_sqr()
        new = True
        if ti.static(only_new):
            new = j != i and (self.marked[q] == 0 or j > i)
        if dd < sigma * sigma and new:
            s = self.contact_time(i, j, d, self.rel_velocity(i, j), sigma)
            if ti.static(record):
                if s >= 0:
                    slot = ti.atomic_add(self.debug_count[None], 1)
                    if slot < self.debug_pairs.shape[0]:
                        self.debug_pairs[slot] = ti.Vector([ti.min(i, j), ti.max(i, j)])
            else:
                rel = 1 - ti.sqrt(dd) / sigma
                if s >= 0:
                    ti.atomic_max(self.earliest[i], s)
                    ti.atomic_max(self.earliest[j], s)
                    cj = self.grid.coords(self.grid.cell_of[j])
                    owner = self.grid.linear(self.grid.owner(ci, cj))
                    found = ti.atomic_add(self.active[owner], 1)
                    if found < ti.static(self.perf.recorded_pairs):
                        # oriented as the forward scan meets it, whichever pass found it
                        # (the bits of a collision depend on the order of its spheres)
                        if self.grid.forward(ci, cj, self.grid.slot[i], q):
                            self.cell_pairs[owner, found] = ti.Vector([i, j])
                        else:
                            self.cell_pairs[owner, found] = ti.Vector([j, i])
                    if found == 0:
                        self.active_list[ti.atomic_add(self.n_active[None], 1)] = owner
                    ti.atomic_add(self.params.remaining[None], 1)
                    ti.atomic_max(self.params.open_overlap[None], rel)
                else:
                    ti.atomic_max(self.params.sep_overlap[None], rel)
        return dd

    @ti.func
    def reset_detection_state(self):
        """What every full detection starts from (call at kernel top level). It always
        runs on a freshly built grid, so the distance moved since the build
        (params.moved) starts again from 0."""
        self.params.reset_detection()
        self.params.moved[None] = 0
        self.clear_active(ti.static(self.serial_light))
        ti.loop_config(serialize=ti.static(self.serial_light))
        for i in range(self.state.n_spheres[None]):
            self.earliest[i] = -1
            self.marked[i] = 0      # (slots; normally clear: after an interrupted sweep)
        self.n_touched[None] = 0

    @ti.func
    def _detect_all_body(self):
        """Half-stencil scan of every sphere: fills ``active`` and params.remaining
        (and the near lists, when kept)."""
        self.reset_detection_state()
        if ti.static(self.near_lists):
            self.near_ok[None] = 1
        self.scan_forward(False)

    @ti.func
    def scan_forward(self, record: ti.template()):
        """Examine every pair once: spheres in cell order, the forward half of the
        27-cell stencil walked as 5 rows along z (see grid.FORWARD_ROWS). With near
        lists (not when recording for tests), keep each sphere's pairs closer than
        near_reach and its position."""
        keep = ti.static(self.near_lists and not record)
        ti.loop_config(serialize=ti.static(self.serial_heavy))
        for p in range(self.state.n_spheres[None]):
            i = self.grid.order[p]
            ci = self.grid.coords(self.grid.cell_of[i])
            xi = self.grid.xs[p]
            kept = 0
            for k in range(ti.static(len(FORWARD_ROWS))):
                a0, b0, a1, b1 = self.grid.row_ranges(ci, self.fwd_rows[k])
                if k == 0:
                    a0 = p + 1   # same cell: only spheres after i (ids sorted in a cell)
                for q in range(a0, b0):
                    dd = self.examine(xi, i, q, ci, record, False)
                    if ti.static(keep):
                        kept = self.keep_near(p, q, dd, kept)
                for q in range(a1, b1):
                    dd = self.examine(xi, i, q, ci, record, False)
                    if ti.static(keep):
                        kept = self.keep_near(p, q, dd, kept)
            if ti.static(keep):
                self.near_id[p] = i
                self.n_near[p] = ti.min(kept, ti.static(self.perf.near_capacity))
                self.x_near[p] = xi
                if kept > ti.static(self.perf.near_capacity):
                    self.near_ok[None] = 0

    @ti.func
    def clear_active(self, serial: ti.template()):
        """Zero the counts of the listed cells (left over when a step hit the sweep
        limit) and empty the list."""
        ti.loop_config(serialize=serial)
        for t in range(self.n_active[None]):
            self.active[self.active_list[t]] = 0
        self.n_active[None] = 0

    @ti.func
    def detect_around_touched(self, serial: ti.template(), live=True):
        """Scan of the full stencil (up to 9 rows along z, examine_around) from spheres
        touched in this sweep; a pair of two touched spheres is examined once, from the
        lower id. When many spheres were touched (more than 1 in dense_touched) they are
        visited in cell order, found by their ``marked`` flags: neighbouring visits then
        share cells and cache lines, which in list order (random in space) cost a cache
        miss per row; with few, the list is cheaper than reading every flag."""
        n_t = 0
        if live:
            n_t = self.n_touched[None]
        dense = n_t > self.state.n_spheres[None] // ti.static(self.perf.dense_touched)   # (no i32 overflow)
        if dense:
            n_t = self.state.n_spheres[None]
        # one loop for both orders: a parallel loop costs its launch even when empty
        ti.loop_config(serialize=ti.static(self.serial_heavy or serial))
        for t in range(n_t):
            i = -1
            p = t
            if dense:
                if self.marked[t] != 0:
                    i = self.grid.order[t]
            else:
                i = self.touched[t]
                p = self.grid.slot[i]
            if i >= 0:   # one inlined copy of the scan (compile time)
                self.examine_around(i, p)

    @ti.func
    def examine_around(self, i, p):
        """examine (only_new) sphere i, at slot p of the grid, against every sphere of
        the cells among its 27 that can hold a sphere overlapping it: a neighbour across
        a face only if i is within r_i + r_max + M of that face, M = params.moved (no
        sphere moved farther since the grid was built; plus a round-off margin): the
        same pairs as all 27 cells (prune_walks = False), with fewer rows and cells
        visited."""
        ci = self.grid.coords(self.grid.cell_of[i])
        xi = self.grid.xs[p]
        lower = ti.Vector([1, 1, 1])
        upper = ti.Vector([1, 1, 1])
        if ti.static(self.perf.prune_walks):
            reach = self.state.rad(i) + self.params.moved[None] + self.walk_reach[None]
            lower, upper = self.grid.sides_within(self.min_image(xi - self.grid.corner(ci)), reach)
        for dx in range(-lower[0], upper[0] + 1):
            for dy in range(-lower[1], upper[1] + 1):
                a0, b0, a1, b1 = self.grid.row_ranges(ci, ti.Vector([dx, dy, -lower[2], upper[2]]))
                for q in range(a0, b0):
                    self.examine(xi, i, q, ci, False, True)
                for q in range(a1, b1):
                    self.examine(xi, i, q, ci, False, True)
