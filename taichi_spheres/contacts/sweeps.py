"""Colour sweeps: resolve the detected pairs colour by colour, then re-detect around
the spheres that moved.

Parallel resolution: see :mod:`taichi_spheres.grid` for ownership and colours. One
thread per owner cell of the current colour repeatedly picks, among the overlapping
approaching pairs of its block, the one with the earliest contact (largest ``s``)
and collides it, as many times as the detection pass counted pairs for that cell.
Spheres a collision touched are re-examined against all their neighbours in the
next sweep.

A mixin of :class:`taichi_spheres.contacts.Contacts` (its fields and options).
"""

import taichi as ti

from ..grid import BLOCK_PAIRS

#: Most colours a grid can have: 3 per axis (an odd periodic axis).
MAX_COLOURS = 27


class ColourSweeps:
    """Bucketing the owner cells by colour, resolving each cell's pairs earliest
    first, and the sweep that follows (walls, grid refresh, re-detection)."""

    @ti.func
    def pair_contact(self, i, j):
        """Time since contact of (i, j) if it is a contact to resolve now, else -1 [s]."""
        s = ti.cast(-1, self.real)
        d, sigma = self.separation(i, j)
        if d.norm_sqr() < sigma * sigma:
            s = self.contact_time(i, j, d, self.rel_velocity(i, j), sigma)
        return s

    @ti.func
    def eligible(self, i, j, s):
        """Pair (i, j) with contact time s may be collided now: it is the earliest
        contact of both spheres as detected. Otherwise it waits for the next sweep (its
        spheres are marked so that the next detection looks at them again)."""
        ok = s >= 0 and s == self.earliest[i] and s == self.earliest[j]
        if s >= 0 and not ok:
            self.mark_touched(i)
            self.mark_touched(j)
        return ok

    @ti.func
    def earliest_in_block(self, c):
        """The eligible pair to resolve owned by cell c (vec3) with the earliest contact
        (largest s): (i, j, s), or i = -1. Reads only spheres in c + {0,1}^3."""
        best_s = ti.cast(-1, self.real)
        bi = -1
        bj = -1
        for k in range(ti.static(len(BLOCK_PAIRS))):
            ca, oka = self.grid.shifted(c, self.block[k, 0])
            cb, okb = self.grid.shifted(c, self.block[k, 1])
            if oka and okb:
                ka = self.grid.linear(ca)
                kb = self.grid.linear(cb)
                for pa in range(self.grid.start[ka], self.grid.start[ka + 1]):
                    i = self.grid.order[pa]
                    q0 = self.grid.start[kb]
                    if k == 0:
                        q0 = pa + 1
                    for q in range(q0, self.grid.start[kb + 1]):
                        j = self.grid.order[q]
                        s = self.pair_contact(i, j)
                        if s > best_s and self.eligible(i, j, s):
                            best_s = s
                            bi = i
                            bj = j
        return bi, bj, best_s

    @ti.func
    def resolve_cell(self, c, k):
        """Collide the pairs owned by cell c (vec3, linear index k), earliest contact
        first, as many as the last detection counted there (at most
        max_block_collisions): each time the earliest among the pairs cell_pairs
        recorded when it holds them all, else by searching the block."""
        budget = ti.min(self.active[k], ti.static(self.perf.max_block_collisions))
        for _it in range(budget):
            bi = -1
            bj = -1
            s = ti.cast(-1, self.real)
            if budget <= ti.static(self.perf.recorded_pairs):
                bi, bj, s = self.earliest_recorded(k, budget)
            else:
                bi, bj, s = self.earliest_in_block(c)
            if bi < 0:
                break
            self.collide(bi, bj, s)   # (one inlined copy: compile time, and equal bits)
        self.active[k] = 0

    @ti.func
    def earliest_recorded(self, k, count):
        """What earliest_in_block finds, searching only the count (1 or 2) pairs cell k
        recorded: (i, j, s) of the eligible one with the earliest contact, or i = -1
        (on a tie the pair with the lower sphere ids: the record's order depends on
        threads). Each pair is checked as it is now (pair_contact): an earlier colour
        or the other pair may have changed it since the detection; eligible() runs on
        both, so a pair that must wait marks its spheres for the next sweep."""
        a = self.cell_pairs[k, 0]
        b = a
        if ti.static(self.perf.recorded_pairs == 2):
            if count == 2:
                b = self.cell_pairs[k, 1]
                lo_a = ti.min(a[0], a[1])
                lo_b = ti.min(b[0], b[1])
                if lo_b < lo_a or (lo_b == lo_a and ti.max(b[0], b[1]) < ti.max(a[0], a[1])):
                    t = a
                    a = b
                    b = t
        bi = -1
        bj = -1
        best = ti.cast(-1, self.real)
        for m in range(count):    # a, then b: one inlined copy of the pair's tests
            pair = a
            if m == 1:
                pair = b
            s = self.pair_contact(pair[0], pair[1])
            # (s > -1 holds where eligible; Taichi's `and` evaluates both sides)
            if s > best and self.eligible(pair[0], pair[1], s):
                bi = pair[0]
                bj = pair[1]
                best = s
        return bi, bj, best

    @ti.func
    def colour_index(self, c):
        """Colour of cell c (vec3): parity per axis, 2 for the last cell of an odd
        periodic axis; numbered like GridGeometry.colours."""
        idx = 0
        dims = self.grid.dims[None]
        odd_last = self.odd_last[None]
        per_axis = self.axis_colours[None]
        for a in ti.static(range(3)):
            ia = c[a] % 2
            if ti.static(self.grid.periodic[a]):
                if odd_last[a] == 1 and c[a] == dims[a] - 1:
                    ia = 2
            idx = idx * per_axis[a] + ia
        return idx

    @ti.func
    def bucket_by_colour(self, serial: ti.template()):
        """Counting sort of the listed cells (active_list[0:n_active]) by colour into
        ``by_colour``: colour c's cells are by_colour[colour_start[c]:colour_start[c+1]]
        (order inside a colour is thread-dependent and irrelevant: its blocks are
        disjoint). Call at kernel top level (or where everything runs serially, as in
        the fused step)."""
        # (the zeroing and the prefix sum as serial runtime loops: unrolled, their 55
        # statements were over a quarter of the field accesses sweep_serial compiled)
        ti.loop_config(serialize=True)
        for c in range(MAX_COLOURS + 1):
            self.colour_start[c] = 0
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_active[None]):
            col = self.colour_index(self.grid.coords(self.active_list[t]))
            ti.atomic_add(self.colour_start[col + 1], 1)
        ti.loop_config(serialize=True)
        for c in range(MAX_COLOURS):
            self.colour_start[c + 1] += self.colour_start[c]
            self.colour_fill[c] = self.colour_start[c]
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_active[None]):
            k = self.active_list[t]
            slot = ti.atomic_add(self.colour_fill[self.colour_index(self.grid.coords(k))], 1)
            self.by_colour[slot] = k

    @ti.func
    def resolve_bucketed(self, t):
        """Resolve the cell at by_colour[t] if it still has pairs."""
        k = self.by_colour[t]
        if self.active[k] > 0:
            self.resolve_cell(self.grid.coords(k), k)

    @ti.func
    def resolve_colour(self, colour, serial: ti.template()):
        """One parallel pass over the cells of one colour (after bucket_by_colour);
        their blocks are disjoint, so no two threads touch one sphere."""
        ti.loop_config(serialize=ti.static(self.serial_heavy or serial))
        for t in range(self.colour_start[colour], self.colour_start[colour + 1]):
            self.resolve_bucketed(t)

    @ti.func
    def resolve_colours_serially(self):
        """The colours one after another in one serial loop (one launch): for small
        systems on the CPU, where a launch per colour costs more than the work. The
        bucketed list is in colour order, so one pass over it is every colour in turn."""
        self.bucket_by_colour(True)
        ti.loop_config(serialize=True)
        for t in range(self.n_active[None]):
            self.resolve_bucketed(t)

    @ti.func
    def after_sweep(self, serial: ti.template()):
        """Put the spheres a sweep touched back inside the box (a wall bounce there
        counts toward the grid's move bound, params.moved), copy their positions into
        grid.xs, detect new approaching overlaps around them, and clear their marks."""
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_touched[None]):
            i = self.touched[t]
            self.motion.contain(i)
            # a wall bounce moves the sphere too: fold it into the grid's move bound
            ti.atomic_max(self.params.moved[None], self.state.moved[i])
            self.grid.refresh(i)
            self.earliest[i] = -1
        self.params.reset_detection()
        self.clear_active(ti.static(self.serial_light or serial))
        self.detect_around_touched(serial)
        self.clear_marks(serial)

    @ti.func
    def clear_marks(self, serial: ti.template()):
        """Clear the touched spheres' marks and empty their list (kernel top level)."""
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_touched[None]):
            self.marked[self.grid.slot[self.touched[t]]] = 0
        self.n_touched[None] = 0

    @ti.func
    def serial_sweeps(self, max_sweeps):
        """Sweeps run serially one after another (resolve_colours_serially, then
        after_sweep) while approaching overlaps remain, at most max_sweeps of them, and
        not after one that found a sphere moved past the grid's slack (the caller must
        rebuild the grid); returns how many ran. Call where everything runs serially
        (the fused step)."""
        done = 0
        while self.params.remaining[None] > 0 and done < max_sweeps:
            self.resolve_colours_serially()
            self.after_sweep(True)
            done += 1
            if self.status() % 2 == 1:
                break
        return done
