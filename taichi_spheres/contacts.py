"""Pair contacts (step stages 3-4): parallel detection, rewind to contact, collide per colour.

Physics (DESIGN.md; the seed paper's eqs. (8)-(14) written without angles):
for spheres i, j with unit normal ``n = (x_i - x_j)/|x_i - x_j|`` at contact and
relative velocity ``u = v_i - v_j`` approaching (``u.n < 0``),
``J = (1 + e) m_i m_j/(m_i + m_j) (u.n)``, ``v_i -= J n/m_i``, ``v_j += J n/m_j``.

Rewind: gravity accelerates both spheres equally, so their relative motion within a
step is linear; with ``d``, ``u`` the relative position and velocity at the end of
the step and ``sigma = r_i + r_j``, the time since contact ``s`` solves
``|d - u s| = sigma``: ``s = (sigma^2 - |d|^2) / (sqrt((d.u)^2 + |u|^2 (sigma^2 - |d|^2)) - d.u)``
(the cancellation-free form of the larger root). The impulse is applied at contact
and carried forward: ``x_i += dv_i s``, ``v_i += dv_i`` (gravity drops out). Pairs
found overlapping but already separating are collided too when they entered during
this step (the step went past their closest approach), see ``contact_time``.

Parallel resolution: see :mod:`taichi_spheres.grid` for ownership and colours. One
thread per owner cell of the current colour repeatedly picks, among the overlapping
approaching pairs of its block, the one with the earliest contact (largest ``s``)
and collides it, as many times as the detection pass counted pairs for that cell.
Spheres a collision touched are re-examined against all their neighbours in the
next sweep.

Near lists (:meth:`Contacts.detect`, from 3,000 spheres on): a full scan keeps each
sphere's forward neighbours closer than the narrowest cell; later detections examine
only those pairs, plus every neighbour of the spheres that moved more than half the
spare reach since (they are scanned around in the grid), until too many have.
"""

import numpy as np
import taichi as ti

from .config import DEFAULT, Tuning
from .grid import BLOCK_PAIRS, FORWARD_ROWS, Grid
from .params import (E_PAIRS, E_REST, MOVED, OPEN_OVERLAP, PAIRS, REMAINING, RESTED,
                     SEP_OVERLAP, SUPPORTED, VIRIAL, VMAX2, StepParams)
from .state import Features, SphereState
from .walls import Motion


#: Most colours a grid can have: 3 per axis (an odd periodic axis).
MAX_COLOURS = 27

def near_allowance(geom, r_max, safety=DEFAULT.performance.near_safety):
    """(reach, allowance) of near lists on grid ``geom`` with largest radius r_max [m]:
    a full scan visits every pair closer than ``reach`` (the narrowest cell; an axis
    of at most 2 cells without wrap has every pair adjacent), so a list of those pairs
    still holds every pair that can overlap while no sphere has moved more than
    ``allowance`` = (reach - 2 r_max)/2 x safety (Performance.near_safety) since the list was made (two
    spheres close in by at most twice that). allowance <= 0: lists are of no use."""
    reach = min((c for c, d, per in zip(geom.cell, geom.dims, geom.periodic)
                 if per or d > 2), default=float("inf"))
    if reach == float("inf"):
        return reach, 0.0
    return reach, safety * 0.5 * (reach - 2.0 * r_max)


def decode_status(status: int):
    """(remaining approaching overlaps, grid must be rebuilt) from a detection status
    (:meth:`Contacts.status`, returned by ``detect_all`` and ``sweep``)."""
    return status >> 1, bool(status & 1)


@ti.data_oriented
class Contacts:
    """Detection and colour-by-colour resolution of overlapping approaching pairs.

    Fields: active (M,) i32 — approaching overlapping pairs owned by each cell, found
    by the last detection pass; cell_pairs (M, recorded_pairs) vec2 i32 — the first
    of them found (in thread-dependent order); active_list
    (M,) / n_active — the cells with active > 0; touched (N,) / n_touched — spheres a
    sweep changed; marked (N,) i32 — 1 at the grid slot (``grid.slot``) of each of
    them, so that scans read the flag of a neighbour from contiguous memory and the
    re-detection can visit the touched spheres in cell order.

    Near lists (near_lists=True, see :meth:`detect`), indexed by the grid slot a
    sphere had when the list was made: near_id (N,) i32 — that sphere; near (N,
    near_capacity) i32 — the spheres its forward scan found closer than
    ``near_reach``; n_near (N,) i32 — how many; x_near (N,) vec3 — its position then;
    near_ok () i32 — 1 when the last full scan fitted every sphere's list.
    """

    def __init__(self, state: SphereState, grid: Grid, params: StepParams, motion: Motion,
                 features: Features, serial_light: bool, serial_heavy: bool,
                 serial_few: bool = False, near_lists: bool = False, tuning: Tuning = DEFAULT):
        self.rules = tuning.physics
        self.perf = tuning.performance
        self.state = state
        self.grid = grid
        self.params = params
        self.motion = motion
        self.f = features
        self.real = state.real
        self.serial_light = serial_light
        self.serial_heavy = serial_heavy
        # only worth a second compiled variant where the loops are otherwise parallel
        self.serial_few = serial_few and not serial_heavy
        eps = float(np.finfo(np.float64 if self.real == ti.f64 else np.float32).eps)
        self.approach_eps = 8.0 * eps
        cells = grid.cell_capacity
        cap = state.capacity
        self.active = ti.field(ti.i32, shape=cells)
        # the first pairs the detection counted for a cell (all of them when it found
        # at most recorded_pairs), oriented as the forward scan meets them
        self.cell_pairs = ti.Vector.field(2, ti.i32, shape=(cells, self.perf.recorded_pairs))
        # stencils as small tables walked by runtime loops (unrolling them multiplies
        # compile time)
        self.fwd_rows = ti.Vector.field(4, ti.i32, shape=len(FORWARD_ROWS))
        self.fwd_rows.from_numpy(np.array(FORWARD_ROWS, dtype=np.int32))
        self.block = ti.Vector.field(3, ti.i32, shape=(len(BLOCK_PAIRS), 2))
        self.block.from_numpy(np.array(BLOCK_PAIRS, dtype=np.int32))
        self.colours = ()
        # colours per axis (1-3) and 1 where the last cell of an odd periodic axis has
        # a colour of its own (see colour_index), of the bound geometry
        self.axis_colours = ti.Vector.field(3, ti.i32, shape=())
        self.odd_last = ti.Vector.field(3, ti.i32, shape=())
        # compact lists, so that sweeps cost O(pairs) and not O(N + cells): the cells
        # with pending pairs, and the spheres a sweep touched (order is thread-dependent,
        # but every use is order-independent: disjoint blocks, per-sphere updates)
        self.active_list = ti.field(ti.i32, shape=cells)
        self.n_active = ti.field(ti.i32, shape=())
        # the listed cells sorted by colour (bucket_by_colour), and where each starts
        self.by_colour = ti.field(ti.i32, shape=cells)
        self.colour_start = ti.field(ti.i32, shape=MAX_COLOURS + 1)
        self.colour_fill = ti.field(ti.i32, shape=MAX_COLOURS)
        self.touched = ti.field(ti.i32, shape=cap)
        self.marked = ti.field(ti.i32, shape=cap)
        # per sphere, the earliest contact (largest time since contact) among its pairs
        # found by the last detection: a pair is collided only when it is the earliest
        # contact of both its spheres, so colours do not reorder one sphere's collisions
        self.earliest = ti.field(self.real, shape=cap)
        self.n_touched = ti.field(ti.i32, shape=())
        # scene values the kernels read (bind): half the common mass [kg] (equal
        # masses), the reach of a pruned walk beyond r_i (r_max + round-off margin) [m]
        self.half_m0 = ti.field(self.real, shape=())
        self.walk_reach = ti.field(self.real, shape=())
        self.debug_pairs = None     # allocated by list_overlaps (tests only)
        self.near_lists = near_lists
        self.near_ready = False     # a full scan made a complete list (Python's copy)
        if self.near_lists:
            # squared reach and allowance of the lists [m^2] (bind)
            self.near_reach2 = ti.field(self.real, shape=())
            self.near_allowance2 = ti.field(self.real, shape=())
            # indexed by the grid slot the sphere had when its list was made, so that
            # the scan writes them in order
            self.near_id = ti.field(ti.i32, shape=cap)
            self.near = ti.field(ti.i32, shape=(cap, self.perf.near_capacity))
            self.n_near = ti.field(ti.i32, shape=cap)
            self.x_near = ti.Vector.field(3, self.real, shape=cap)
            self.near_ok = ti.field(ti.i32, shape=())

        # hot kernels as plain closures: a data_oriented method kernel pays ~40 us of
        # Python dispatch per launch for its `self` template argument
        # kernels that end a detection return its status (see status()): one launch
        # instead of a launch plus two scalar reads per sweep

        @ti.kernel
        def detect_all() -> ti.i32:
            self._detect_all_body()
            return self.status()

        @ti.kernel
        def detect_near() -> ti.i32:
            self.reset_detection_state()
            self.mark_fast_movers()
            live = self.near_live()
            self.scan_near(live)
            self.detect_around_touched(False, live)
            self.clear_marks(False)
            out = -1
            if live:
                out = self.status()
            return out

        @ti.kernel
        def bucket_parallel():
            self.bucket_by_colour(False)

        @ti.kernel
        def resolve_colour_parallel(colour: ti.i32):
            self.resolve_colour(colour, False)

        @ti.kernel
        def sweep_serial() -> ti.i32:
            self.resolve_colours_serially()
            self.after_sweep(True)
            return self.status()

        @ti.kernel
        def sweep_mixed() -> ti.i32:
            self.resolve_colours_serially()
            self.after_sweep(False)
            return self.status()

        @ti.kernel
        def after_sweep_parallel() -> ti.i32:
            self.after_sweep(False)
            return self.status()


        self.detect_all = detect_all
        self.detect_near = detect_near if self.near_lists else None
        self.bucket_parallel = bucket_parallel
        self.resolve_colour_parallel = resolve_colour_parallel
        self.sweep_serial = sweep_serial
        self.sweep_mixed = sweep_mixed
        self.after_sweep_parallel = after_sweep_parallel

    def bind(self, scene, geom):
        """Load what the kernels read of a scene and its grid geometry ``geom`` (after
        state.bind and grid.bind); forget the near lists and any pending pairs."""
        self.n = scene.n
        self.colours = geom.colours
        self.axis_colours[None] = [len(geom.axis_colours(a)) for a in range(3)]
        self.odd_last[None] = [int(p and d % 2 == 1) for p, d in zip(geom.periodic, geom.dims)]
        self.half_m0[None] = 0.5 * float(scene.mass[0])
        # round-off allowance of the cells a walk skips (examine_around) [m]: positions
        # and cell faces carry a few eps of the largest coordinate
        eps = self.approach_eps / 8.0
        extent = max(max(abs(a), abs(b)) for a, b in zip(scene.box_lo, scene.box_hi))
        r_max = float(scene.radius.max())
        self.walk_reach[None] = r_max + 64.0 * eps * (extent + max(geom.cell))
        self.near_reach, allowance = near_allowance(geom, r_max, self.perf.near_safety)
        if self.near_lists:
            if not allowance > 0:
                raise ValueError("near lists need cells wider than the largest diameter")
            self.near_reach2[None] = self.near_reach ** 2
            self.near_allowance2[None] = allowance * allowance
        self.near_ready = False
        self.active.fill(0)
        self.n_active[None] = 0
        self.n_touched[None] = 0

    # ---- pair geometry and physics ----
    @ti.func
    def separation(self, i, j):
        """d = x_i - x_j (minimum image on periodic axes) [m] and sigma = r_i + r_j [m].
        Velocities are loaded separately, only for overlapping pairs."""
        return self.separation_between(self.state.x[i], self.state.x[j], i, j)

    @ti.func
    def separation_between(self, xi, xj, i, j):
        """separation(i, j) with both positions loaded (scans read them from grid.xs)."""
        return self.min_image(xi - xj), self.state.rad(i) + self.state.rad(j)

    @ti.func
    def min_image(self, d):
        """Difference d of two positions [m], shifted to its minimum image on periodic
        axes. Positions stay within about one box length of each other, so one
        compare-and-shift does (no division in the hot loop)."""
        box = self.params.size[None]
        for a in ti.static(range(3)):
            if ti.static(not self.f.wall_axes[a]):
                size = box[a]
                if d[a] > 0.5 * size:
                    d[a] -= size
                elif d[a] < -0.5 * size:
                    d[a] += size
        return d

    @ti.func
    def rel_velocity(self, i, j):
        """u = v_i - v_j [m/s]."""
        return self.state.v[i] - self.state.v[j]

    @ti.func
    def approaching(self, dd, du, uu, ss):
        """d.u < 0 beyond round-off: relative to |d| times the velocities' scale,
        sqrt(|u|^2 + |v_i|^2 + |v_j|^2) (ss = |v_i|^2 + |v_j|^2 [m^2/s^2]). The speeds
        count too: after a perfectly inelastic collision of spheres in motion the
        relative velocity is round-off of their speeds, pointing anywhere, and must not
        count as an approach (it would be collided again and again)."""
        return du < -ti.cast(ti.static(self.approach_eps), self.real) * ti.sqrt(dd * (uu + ss))

    @ti.func
    def resting(self, i, j):
        """The rest rule applies to pair (i, j): always when the scene set a rest speed
        without gravity; with gravity (supports) only when one of the two spheres is
        supported in this step (a contact of a pile, not of a gas in flight)."""
        out = True
        if ti.static(self.f.supports):
            out = self.state.support[i] == 1 or self.state.support[j] == 1
        return out

    @ti.func
    def approaching_pair(self, i, j, dd, du, uu, ss):
        """approaching(), and for a resting contact (see resting()) faster than
        rules.rest_tolerance x the rest speed: a slower one is left alone (it closes the gap by
        less than that speed x h per step; gravity makes it faster by g h in the next)."""
        out = self.approaching(dd, du, uu, ss)
        if ti.static(self.f.rest_rule):
            if out and self.resting(i, j):
                out = du * du > ti.static(self.rules.rest_tolerance ** 2) * self.params.rest_speed[None] ** 2 * dd
        return out

    @ti.func
    def contact_time(self, i, j, d, u, sigma):
        """For an overlapping pair (|d| < sigma; d, u relative position and velocity at
        the end of the step): the time s since it came into contact if that contact is
        to be resolved now, else -1 [s]. |d - u s| = sigma is solved by the
        cancellation-free root s = (sigma^2 - |d|^2) / (sqrt((d.u)^2 + |u|^2 (sigma^2 -
        |d|^2)) - d.u). A pair is resolved if it approaches now (s capped at the step
        length), or if it already passed its closest approach but entered during this
        step (s <= h) while approaching: a collision the step went through. A pair that
        was already overlapping when the step began and now separates (left over from
        out-of-order resolution) is not."""
        dd = d.norm_sqr()
        du = d.dot(u)
        uu = u.norm_sqr()
        h = self.params.h[None]
        out = ti.cast(-1, self.real)
        if uu > 0:
            ss = self.state.v[i].norm_sqr() + self.state.v[j].norm_sqr()
            c = sigma * sigma - dd
            s = c / (ti.sqrt(du * du + uu * c) - du)
            if self.approaching_pair(i, j, dd, du, uu, ss):
                out = ti.min(s, h)
            elif s <= h:
                dc = d - u * s
                if self.approaching(dc.norm_sqr(), dc.dot(u), uu, ss):
                    out = s
        return out

    @ti.func
    def collide(self, i, j, s):
        """Rewind i, j by s to contact, apply the restitution impulse, carry forward.

        Restitution (see the module docstring): "normal" u_n' = -e u_n with the
        tangential relative velocity unchanged; "smid" (Features.smid) the seed's rule
        after Smid (2007), u' = e (u - 2 u_n n): the whole relative velocity of the
        elastic result scaled by e about the centre of mass. Rest rule
        (Features.rest_rule): an approach slower than the rest speed is perfectly
        inelastic in the normal direction (u_n' = 0, tangential kept) whatever the
        model. Supports (Features.supports): such a slow contact whose normal is
        within about 66 degrees of vertical (rules.support_cos), with a supported sphere below (on the floor,
        or itself stopped by a supported sphere in this step) and an unsupported one
        above, stops the upper sphere's approach without moving the lower one (the
        floor carries the load: shock propagation, Guendelman et al. 2003), unless
        that would raise the upper sphere's kinetic energy; the upper sphere is then
        supported. Energy removed is booked per cause (vals E_PAIRS, E_REST)."""
        d, sigma = self.separation(i, j)
        u = self.rel_velocity(i, j)
        rc = d - u * s
        n = rc.normalized()
        un = u.dot(n)
        if un < 0:
            e = ti.cast(1, self.real)
            if ti.static(not self.f.elastic):
                e = self.params.e[None]
            rest = False
            if ti.static(not self.f.elastic):
                # collapse rule: from a sphere's rules.collapse_hits-th collision in one
                # step on, its collisions are perfectly inelastic (normal), so that
                # dense clusters cannot collide without end within a step; inelastic
                # pairs only (e < 1 checked here too: compiled in with e = 1 it must
                # not change the physics)
                rest = e < 1 and ti.max(self.state.hits[i], self.state.hits[j]) >= ti.static(self.rules.collapse_hits - 1)
            if ti.static(self.f.rest_rule):
                rest = rest or (-un < self.params.rest_speed[None] and self.resting(i, j))
            wi = ti.cast(0.5, self.real)
            wj = ti.cast(0.5, self.real)
            meff = self.half_m0[None]
            if ti.static(not self.f.equal_masses):
                imi = self.state.inv_mass_of(i)
                imj = self.state.inv_mass_of(j)
                wi = imi / (imi + imj)
                wj = imj / (imi + imj)
                meff = 1 / (imi + imj)
            dvi = ti.Vector.zero(self.real, 3)
            dvj = ti.Vector.zero(self.real, 3)
            done = False
            if ti.static(self.f.supports):
                if rest:
                    done, dvi, dvj = self.supported_stop(i, j, n, un, s)
            if not done:
                if rest:
                    dvi = -un * wi * n
                    dvj = un * wj * n
                    ti.atomic_add(self.params.vals[E_REST], 0.5 * meff * un * un)
                    ti.atomic_add(self.params.count[RESTED], 1)
                else:
                    du = -(1 + e) * un * n
                    loss = 0.5 * meff * (1 - e * e) * un * un
                    if ti.static(self.f.smid):
                        # u' = e (u - 2 u_n n): du = u' - u
                        du = e * (u - 2 * un * n) - u
                        loss = 0.5 * meff * (1 - e * e) * u.norm_sqr()
                    dvi = wi * du
                    dvj = -wj * du
                    if ti.static(not self.f.elastic):
                        ti.atomic_add(self.params.vals[E_PAIRS], loss)
            self.state.x[i] += dvi * s
            self.state.v[i] += dvi
            self.state.x[j] += dvj * s
            self.state.v[j] += dvj
            self.mark_touched(i)
            self.mark_touched(j)
            self.state.moved[i] += dvi.norm() * s
            self.state.moved[j] += dvj.norm() * s
            self.motion.count_hit(i)
            self.motion.count_hit(j)
            # virial r_ij . dp_i with r_ij the contact separation (j to i)
            ti.atomic_add(self.params.vals[VIRIAL], rc.dot(dvi) * self.state.mass_of(i))
            ti.atomic_add(self.params.count[PAIRS], 1)
            ti.atomic_max(self.params.vals[VMAX2], ti.max(self.state.v[i].norm_sqr(), self.state.v[j].norm_sqr()))
            ti.atomic_max(self.params.vals[MOVED], ti.max(self.state.moved[i], self.state.moved[j]))

    @ti.func
    def supported_stop(self, i, j, n, un, s):
        """The supported-contact rule of :meth:`collide` for a slow approach (u_n =
        un < 0, n from j to i, contact s ago): (applied, dv_i, dv_j). Only the upper
        sphere changes: by dv now and dv s in position (carried forward), so its
        energy changes by m (|v + dv|^2 - |v|^2)/2 - m g.dv s (momentum is not
        conserved: the support takes it). Applied only if that change is not
        positive (beyond round-off); then the upper sphere is supported and the
        loss is booked to the rest rule."""
        done = False
        dvi = ti.Vector.zero(self.real, 3)
        dvj = ti.Vector.zero(self.real, 3)
        up = n.dot(self.params.up[None])
        upper = -1
        si = self.state.support[i]
        sj = self.state.support[j]
        if up > ti.static(self.rules.support_cos) and sj == 1 and si == 0:
            upper = i
            dvi = -un * n          # (v_i' - v_j).n = 0
        elif up < -ti.static(self.rules.support_cos) and si == 1 and sj == 0:
            upper = j
            dvj = un * n           # (v_i - v_j').n = 0
        if upper >= 0:
            dv = dvi + dvj
            v = self.state.v[upper]
            lift = -self.params.gravity[None].dot(dv) * s
            gain = 0.5 * ((v + dv).norm_sqr() - v.norm_sqr()) + lift
            # round-off: of the kinetic terms, and of the potential energy at the
            # sphere's height (positions carry eps |x| of noise: spheres sitting
            # on each other overlap by that much)
            g = self.params.gravity[None].norm()
            scale = 0.5 * v.norm_sqr() + ti.abs(lift) + g * (self.state.x[upper].norm() + self.state.rad(upper))
            if gain <= ti.static(2 * self.approach_eps) * scale:
                done = True
                self.state.support[upper] = 1
                ti.atomic_add(self.params.vals[E_REST], -self.state.mass_of(upper) * gain)
                ti.atomic_add(self.params.count[RESTED], 1)
                ti.atomic_add(self.params.count[SUPPORTED], 1)
        return done, dvi, dvj

    @ti.func
    def mark_touched(self, i):
        if ti.atomic_or(self.marked[self.grid.slot[i]], 1) == 0:
            self.touched[ti.atomic_add(self.n_touched[None], 1)] = i

    # ---- detection ----
    @ti.func
    def status(self):
        """2 x count[REMAINING] (approaching overlaps found by the last detection) + 1
        if a sphere moved farther than the grid's slack since the grid was built (the
        grid must be rebuilt before the next sweep). Decode with :func:`decode_status`."""
        far = 0
        if self.params.vals[MOVED] > self.grid.slack[None]:
            far = 1
        return 2 * self.params.count[REMAINING] + far

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
                    ti.atomic_add(self.params.count[REMAINING], 1)
                    ti.atomic_max(self.params.vals[OPEN_OVERLAP], rel)
                else:
                    ti.atomic_max(self.params.vals[SEP_OVERLAP], rel)
        return dd

    @ti.func
    def reset_detection_state(self):
        """What every full detection starts from (call at kernel top level). It always
        runs on a freshly built grid, so the distance moved since the build
        (vals[MOVED]) starts again from 0."""
        self.params.reset_detection()
        self.params.vals[MOVED] = 0
        self.clear_active(ti.static(self.serial_light))
        ti.loop_config(serialize=ti.static(self.serial_light))
        for i in range(self.state.n_spheres[None]):
            self.earliest[i] = -1
            self.marked[i] = 0      # (slots; normally clear: after an interrupted sweep)
        self.n_touched[None] = 0

    @ti.func
    def _detect_all_body(self):
        """Half-stencil scan of every sphere: fills ``active`` and count[REMAINING]
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

    # ---- detection from near lists ----
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
        a face only if i is within r_i + r_max + M of that face, M = vals[MOVED] (no
        sphere moved farther since the grid was built; plus a round-off margin): the
        same pairs as all 27 cells (prune_walks = False), with fewer rows and cells
        visited."""
        ci = self.grid.coords(self.grid.cell_of[i])
        xi = self.grid.xs[p]
        lower = ti.Vector([1, 1, 1])
        upper = ti.Vector([1, 1, 1])
        if ti.static(self.perf.prune_walks):
            reach = self.state.rad(i) + self.params.vals[MOVED] + self.walk_reach[None]
            lower, upper = self.grid.sides_within(self.min_image(xi - self.grid.corner(ci)), reach)
        for dx in range(-lower[0], upper[0] + 1):
            for dy in range(-lower[1], upper[1] + 1):
                a0, b0, a1, b1 = self.grid.row_ranges(ci, ti.Vector([dx, dy, -lower[2], upper[2]]))
                for q in range(a0, b0):
                    self.examine(xi, i, q, ci, False, True)
                for q in range(a1, b1):
                    self.examine(xi, i, q, ci, False, True)

    # ---- resolution ----
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
        sa = self.pair_contact(a[0], a[1])
        if self.eligible(a[0], a[1], sa):
            bi = a[0]
            bj = a[1]
            best = sa
        if count == 2:
            sb = self.pair_contact(b[0], b[1])
            if sb > best and self.eligible(b[0], b[1], sb):
                bi = b[0]
                bj = b[1]
                best = sb
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
        for c in ti.static(range(MAX_COLOURS + 1)):
            self.colour_start[c] = 0
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_active[None]):
            col = self.colour_index(self.grid.coords(self.active_list[t]))
            ti.atomic_add(self.colour_start[col + 1], 1)
        for c in ti.static(range(MAX_COLOURS)):
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
        counts toward the grid's move bound, vals[MOVED]), copy their positions into
        grid.xs, detect new approaching overlaps around them, and clear their marks."""
        ti.loop_config(serialize=ti.static(self.serial_light or serial))
        for t in range(self.n_touched[None]):
            i = self.touched[t]
            self.motion.walls_and_wrap(i)
            # a wall bounce moves the sphere too: fold it into the grid's move bound
            ti.atomic_max(self.params.vals[MOVED], self.state.moved[i])
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
        while self.params.count[REMAINING] > 0 and done < max_sweeps:
            self.resolve_colours_serially()
            self.after_sweep(True)
            done += 1
            if self.status() % 2 == 1:
                break
        return done

    def detect(self):
        """Full detection (fills ``active`` and count[REMAINING]) on a freshly built
        grid; returns (status, from_list). From the near lists while they are
        complete and at most 1 sphere in near_fast_limit moved more than the allowance
        since a full scan made them (those are scanned around in the grid), else by a
        full scan, which makes new lists. Both find the same pairs and give the same bits; the list
        examines about 2 pairs per sphere in a gas at packing fraction 0.3 instead of
        the scan's 14 (and its 5 row look-ups)."""
        if self.near_ready:
            status = self.detect_near()
            if status >= 0:
                return status, True
        status = self.detect_all()
        self.near_ready = self.near_lists and bool(self.near_ok[None])
        return status, False

    def sweep(self, pending) -> int:
        """Resolve every colour in turn, then :meth:`after_sweep`; returns the status of
        the new detection (:func:`decode_status`). On the CPU, with few pending pairs
        the loops run serially (a parallel launch there costs more than the work; a
        second compiled variant, built on first use), with more the resolution runs
        serially and the detection in parallel, in one launch; otherwise (and on GPUs)
        the colours run in parallel one launch each. (A kernel looping over sweeps
        would save a launch per sweep but doubles the compile time: see fused.py.)"""
        if self.serial_heavy or (self.serial_few and pending <= self.perf.few_pairs):
            return self.sweep_serial()
        if self.serial_few and pending <= self.perf.serial_resolve_pairs:
            return self.sweep_mixed()
        self.bucket_parallel()
        for k in range(len(self.colours)):
            self.resolve_colour_parallel(k)
        return self.after_sweep_parallel()

    # ---- debugging / tests ----
    def list_overlaps(self):
        """Sorted (K, 2) int array of the overlapping approaching pairs that the
        detection scan finds (same code path as detect_all, recording instead)."""
        if self.debug_pairs is None:
            self.debug_pairs = ti.Vector.field(2, ti.i32, shape=8 * self.state.capacity + 16)
            self.debug_count = ti.field(ti.i32, shape=())

            @ti.kernel
            def record():
                self.debug_count[None] = 0
                self.scan_forward(True)

            self._record = record
        self._record()
        k = int(self.debug_count[None])
        if k > self.debug_pairs.shape[0]:
            raise RuntimeError(f"{k} overlapping pairs: more than the debug list holds")
        pairs = self.debug_pairs.to_numpy()[:k]
        return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]

    @ti.kernel
    def _block_touches(self, sx: ti.i32, dx: ti.i32, nx: ti.i32, sy: ti.i32, dy: ti.i32,
                       ny: ti.i32, sz: ti.i32, dz: ti.i32, nz: ti.i32,
                       touches: ti.types.ndarray()):
        """touches[i] += 1 for each owner cell of one colour whose block holds sphere i."""
        for I in ti.grouped(ti.ndrange(nx, ny, nz)):
            c = ti.Vector([sx + dx * I[0], sy + dy * I[1], sz + dz * I[2]])
            for a in ti.static(range(2)):
                for b in ti.static(range(2)):
                    for e in ti.static(range(2)):
                        cb, ok = self.grid.shifted(c, ti.Vector([a, b, e]))
                        if ok:
                            kb = self.grid.linear(cb)
                            for q in range(self.grid.start[kb], self.grid.start[kb + 1]):
                                ti.atomic_add(touches[self.grid.order[q]], 1)

    def block_touches(self, colour_index):
        """(N,) int: how many owner cells of colour ``colour_index`` may touch each sphere."""
        touches = np.zeros(self.n, dtype=np.int32)
        col = self.colours[colour_index]
        self._block_touches(*col[0], *col[1], *col[2], touches)
        return touches
