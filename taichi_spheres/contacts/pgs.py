"""Projected Gauss–Seidel sweeps of the contact solver (contacts/solver.py): one
update per row, cells of one colour in parallel (on the CPU a few of them per thread,
interleaved: sweep_cells), colours in turn. A serial solve sweeps one list of the rows
in that same order (schedule_rows, sweep_scheduled), from packed copies of the rows
where it has them (contacts/packed.py): the same bits.

Row update (Catto's sequential impulses, Moreau–Jean): with u_n the row's normal
relative velocity (separating > 0), lambda = max(lambda + omega m_eff (target - u_n),
0) and the change applied to both spheres (Rules.relaxation = omega, 1.8 by default).
A sweep's residual is the largest change it made to a velocity, or in the position
pass the largest overlap a row still had when the sweep came to it (target - u_n of
the pseudo-velocities, per step): that pass is there to bring overlaps within
tolerance, and stops once a plain sweep meets none above it (a later update of that
sweep can reopen a row it met: Rules.position_extension's test, solver.overlap_left,
looks at every row after the pass).
Over-relaxed sweeps (omega != 1) overshoot: a solve stops only after a plain sweep
(omega = 1) left every row within tolerance, and the last Rules.plain_sweeps sweeps of
the cap run plain, so a solve stopped at its cap does not keep the overshoot (with
Rules.step_scaled_sweeps, cap and plain sweeps scaled to the step: set_cap).

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti

from .sweeps import MAX_COLOURS

#: modes of one sweep over the rows: apply the warm-start impulses, a velocity update,
#: a position (pseudo-velocity) update
WARM, VELOCITY, POSITION = 0, 1, 2


@ti.pyfunc
def plain_sweep(it, relaxed, cap, last):
    """1 where sweep ``it`` (from 0) of a solve capped at ``cap`` sweeps runs plain
    (omega = 1): the solve is no longer ``relaxed``, or the sweep is among the ``last``
    of the cap (set_cap); else 0 (over-relaxed). Called in kernels (sweep_relaxation)
    and by the host's loop of one launch per sweep (ContactSolver._iterate): one rule."""
    return 1 if (relaxed == 0 or it >= cap - last) else 0


@ti.pyfunc
def next_sweep(it, relaxed, plain, cap, within):
    """(it, relaxed, done) once sweep ``it`` ran: ``within`` (1 where it left every
    row within tolerance) ends the over-relaxation, and the solve after a plain sweep;
    the cap ends it too. Kernels (after_sweep) and the host's loop alike."""
    it += 1
    done = 0
    if within != 0:
        relaxed = 0
        if plain != 0:
            done = 1
    if it >= cap:
        done = 1
    return it, relaxed, done


class GaussSeidel:
    """Row updates, sweeps over one colour's cells, and whole serial iterations."""

    @ti.func
    def inv_mass(self, i):
        """1/m of sphere i [1/kg]."""
        out = self.state.inv_m0[None]
        if ti.static(not self.f.equal_masses):
            out = self.state.inv_mass_of(i)
        return out

    @ti.func
    def push(self, field: ti.template(), a, b, n, impulse):
        """Apply a normal impulse [N s] (or pseudo-impulse) to row (a, b). Plain
        read-modify-write, not ``+=``: a parallel loop would make that an atomic add
        (a compare-and-swap loop per f64 component on the CPU, ~3x the row's cost),
        and the colours already keep two threads off one sphere (same sums, same
        bits). With equal masses both spheres take one product (the same bits as one
        each)."""
        if ti.static(self.f.equal_masses):
            step = impulse * self.state.inv_m0[None] * n
            field[a] = field[a] + step
            if b >= 0:
                field[b] = field[b] - step
        else:
            field[a] = field[a] + impulse * self.inv_mass(a) * n
            if b >= 0:
                field[b] = field[b] - impulse * self.inv_mass(b) * n

    @ti.func
    def solve_row(self, s, mode: ti.template(), omega):
        """Row s in one sweep: WARM applies its warm-start impulse (a pass of its own
        before the iterations, so that every row starts from last step's impulses);
        VELOCITY and POSITION make one projected Gauss-Seidel update (VELOCITY: with
        friction, the friction rows first: contacts/friction_rows.py). Returns its
        residual [m/s]: the velocity change it made (VELOCITY), the overlap it met per
        step (POSITION: update_from's ``violation``), 0 for WARM."""
        out = ti.cast(0, self.real)
        if ti.static(mode == WARM):
            self.push(self.state.v, self.row_a[s], self.row_b[s], self.normal[s], self.lam[s])
            if ti.static(self.f.friction):
                self.warm_friction(s)
        elif ti.static(mode == POSITION):
            out = self.update_row(s, self.w, self.mu, self.pos_target, omega, True)
        elif ti.static(self.f.friction):
            out = self.solve_friction(s)     # friction first, normal last
            out = ti.max(out, self.update_row(s, self.state.v, self.lam, self.target, omega))
        else:
            out = self.update_row(s, self.state.v, self.lam, self.target, omega)
        return out

    @ti.func
    def update_row(self, s, field: ti.template(), acc: ti.template(), goal: ti.template(), omega,
                   violation: ti.template() = False):
        """Row s on velocities ``field`` with accumulated impulse ``acc`` and targets
        ``goal`` (update_from on the row fields)."""
        return self.update_from(s, self.row_a, self.row_b, self.normal, self.meff, field,
                                acc, goal, omega, violation)

    @ti.func
    def update_from(self, s, row_a: ti.template(), row_b: ti.template(),
                    normal: ti.template(), meff: ti.template(), field: ti.template(),
                    acc: ti.template(), goal: ti.template(), omega,
                    violation: ti.template() = False):
        """Row s of the rows (row_a, row_b, normal, meff, acc, goal) on velocities
        ``field``: lambda = max(lambda + omega m_eff (goal - u_n), 0), applying the change;
        returns |change| / m_eff [m/s], halved where halved_residual (full_residual), or
        with ``violation`` (the position pass) max(goal - u_n, 0) before the update [m/s]:
        how far the row still overlapped, per step."""
        a = row_a[s]
        b = row_b[s]
        n = normal[s]
        rel = field[a]
        if b >= 0:
            rel = rel - field[b]
        m = meff[s]
        old = acc[s]
        short = goal[s] - rel.dot(n)
        new = ti.max(old + omega * m * short, 0)
        acc[s] = new
        out = ti.cast(0, self.real)
        if ti.static(violation):
            self.push(field, a, b, n, new - old)
            out = ti.max(short, 0)
        elif ti.static(self.halved_residual):
            out = self.push_halved(field, a, b, n, new - old)
        else:
            self.push(field, a, b, n, new - old)
            out = self.speed_change(ti.abs(new - old), b, m)
        return out

    @ti.func
    def push_halved(self, field: ti.template(), a, b, n, impulse):
        """push with equal masses, whose product impulse / m [m/s] also gives the row's
        residual: |impulse| / m_eff is 2 |impulse / m| for a pair and |impulse / m| for
        a wall row (speed_change), returned halved: |impulse / m| and |impulse / m| / 2.
        Halving and doubling are exact, so full_residual's doubled largest value is
        speed_change's largest (where |impulse / m| is below 2^-1021 m/s in f64,
        2^-125 in f32, far under any tolerance, the last bit may differ); a pair row
        saves speed_change's sum and product."""
        change = impulse * self.state.inv_m0[None]
        step = change * n
        field[a] = field[a] + step
        out = ti.abs(change)
        if b >= 0:
            field[b] = field[b] - step
        else:
            out = out * 0.5
        return out

    @ti.func
    def speed_change(self, impulse, b, meff):
        """The relative speed an impulse [N s] changes in a row of effective mass
        ``meff`` [kg] (impulse / m_eff [m/s], the sweep's residual). With equal masses
        1 / m_eff is 1/m for a wall row (b < 0) and 2/m for a pair: a product instead
        of a division in every row update. The residual may then differ from the
        quotient in its last bit; it only decides when the sweeps stop (and is reported
        as stats["contact_residual"]), so a solve could end a sweep sooner or later
        only where a residual lies within that bit of the tolerance."""
        out = ti.cast(0, self.real)
        if ti.static(self.f.equal_masses):
            inv = self.state.inv_m0[None]
            if b >= 0:
                inv = inv + inv
            out = impulse * inv
        else:
            out = impulse / meff
        return out

    @ti.func
    def rows_of(self, k):
        """Cell k's rows [lo, hi) within the solver's capacity."""
        return self.cell_start[k], ti.min(self.cell_start[k + 1], ti.static(self.capacity))

    @ti.func
    def sweep_cells(self, t, end, mode: ti.template(), omega, k: ti.template()):
        """Cells active_cells[t : min(t + k, end)] of one colour, their rows interleaved:
        row j of each cell, then row j + 1 of each. Each cell's rows stay in order and
        the cells share no sphere, so the bits are those of one cell after the other,
        while the processor overlaps the cells' updates: a row update waits on the
        previous one of its cell (they share a sphere), not on the other cells'. The
        largest residual (full_residual) goes to ``residual``."""
        lo = ti.Vector.zero(ti.i32, k)
        hi = ti.Vector.zero(ti.i32, k)
        longest = 0
        for c in ti.static(range(k)):
            if t + c < end:
                lo[c], hi[c] = self.rows_of(self.active_cells[t + c])
                longest = ti.max(longest, hi[c] - lo[c])
        worst = ti.cast(0, self.real)
        for j in range(longest):
            for c in range(k):
                if lo[c] + j < hi[c]:
                    worst = ti.max(worst, self.solve_row(lo[c] + j, mode, omega))
        ti.atomic_max(self.residual[None], self.full_residual(worst, mode))

    @ti.func
    def sweep_colour(self, colour, mode: ti.template(), omega, batched: ti.template() = False):
        """One parallel pass over the cells of one colour that own rows (disjoint
        blocks: no two threads touch a sphere), in list_active_cells order, k cells at a
        time with their rows interleaved (sweep_cells; k: ContactSolver.
        interleave_parallel; serial sweeps run sweep_scheduled instead). ``batched``: a
        sweep of a batch (batched_sweep): no cell once the batch's solve is done, the
        relaxation from batch_omega instead of ``omega``."""
        start = self.colour_active[colour]
        end = self.colour_active[colour + 1]
        k = ti.static(self.interleave_parallel)
        count = (end - start + k - 1) // k
        if ti.static(batched):
            if self.batch_done[None] != 0:
                count = 0
        ti.loop_config(block_dim=ti.static(self.sweep_block))
        for u in range(count):
            relax = omega
            if ti.static(batched):
                relax = self.batch_omega[None]
            self.sweep_cells(start + k * u, end, mode, relax, k)

    @ti.func
    def schedule_rows(self):
        """The serial sweeps' order of the rows, one list for every colour in turn
        (kernel top level, one serial task): colour c's rows are
        schedule[schedule_start[c]:schedule_start[c + 1]], in sweep_cells' order (its
        cells in groups of ``interleave``, row j of each cell of a group, then row
        j + 1). A serial sweep (sweep_scheduled) then runs one plain loop over the
        list, the same row updates in the same order as sweep_cells (the same bits),
        without sweep_cells' test per cell and row of whether that cell still has a
        row j, which the processor cannot predict where cells hold few rows."""
        k = ti.static(self.interleave)
        ti.loop_config(serialize=True)
        for _ in range(1):
            put = 0
            for colour in range(self.n_colours_f[None]):
                self.schedule_start[colour] = put
                end = self.colour_active[colour + 1]
                t = self.colour_active[colour]
                while t < end:
                    longest = 0
                    for c in range(k):
                        if t + c < end:
                            lo, hi = self.rows_of(self.active_cells[t + c])
                            longest = ti.max(longest, hi - lo)
                    for j in range(longest):
                        for c in range(k):
                            if t + c < end:
                                lo, hi = self.rows_of(self.active_cells[t + c])
                                if lo + j < hi:
                                    self.schedule[put] = lo + j
                                    put += 1
                    t += k
            self.schedule_start[self.n_colours_f[None]] = put

    @ti.func
    def sweep_scheduled(self, colour, mode: ti.template(), omega):
        """One serial pass over colour ``colour``'s rows in schedule order
        (schedule_rows; call where everything runs serially), velocity and position
        updates from the packed rows where the solver keeps them (contacts/packed.py);
        the largest residual (full_residual) goes to ``residual``."""
        worst = ti.cast(0, self.real)
        for t in range(self.schedule_start[colour], self.schedule_start[colour + 1]):
            if ti.static(self.packed and mode == POSITION):
                worst = ti.max(worst, self.update_packed(t, self.w, omega, True))
            elif ti.static(self.packed and mode == VELOCITY):
                worst = ti.max(worst, self.update_packed(t, self.state.v, omega))
            else:
                worst = ti.max(worst, self.solve_row(self.schedule[t], mode, omega))
        self.residual[None] = ti.max(self.residual[None], self.full_residual(worst, mode))

    @ti.func
    def full_residual(self, worst, mode: ti.template()):
        """The residual [m/s] of a sweep whose row updates returned at most ``worst``:
        twice that where velocity updates return it halved (halved_residual:
        push_halved; WARM returns 0, POSITION the largest overlap met, whole)."""
        out = worst
        if ti.static(self.halved_residual and mode == VELOCITY):
            out = worst * 2
        return out

    @ti.func
    def colour_of(self, k):
        """Colour of cell k, numbered like GridGeometry.colours (the pair rule's
        Contacts.colour_index of its coordinates)."""
        return self.pairs.colour_index(self.grid.coords(k))

    @ti.func
    def owns_rows(self, k):
        """Cell k owns rows within the solver's capacity."""
        lo, hi = self.rows_of(k)
        return hi > lo

    @ti.func
    def list_active_cells(self):
        """active_cells: the cells of each colour that own rows; colour c's cells are
        active_cells[colour_active[c]:colour_active[c + 1]] (kernel top level). A count
        per colour, its prefix (a few colours) and a placement, each cell in parallel:
        the order of the cells inside one colour does not change the sweeps' bits
        (their blocks are disjoint); serially it is the cells' linear order."""
        ti.loop_config(serialize=True)
        for colour in range(ti.static(MAX_COLOURS)):
            self.colour_fill[colour] = 0
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.grid.n_cells[None]):
            if self.owns_rows(k):
                ti.atomic_add(self.colour_fill[self.colour_of(k)], 1)
        ti.loop_config(serialize=True)
        for _ in range(1):
            total = 0
            for colour in range(self.n_colours_f[None]):
                self.colour_active[colour] = total
                total += self.colour_fill[colour]
                self.colour_fill[colour] = 0
            self.colour_active[self.n_colours_f[None]] = total
        ti.loop_config(serialize=ti.static(self.serial))
        for k in range(self.grid.n_cells[None]):
            if self.owns_rows(k):
                colour = self.colour_of(k)
                self.active_cells[self.colour_active[colour] +
                                  ti.atomic_add(self.colour_fill[colour], 1)] = k

    @ti.func
    def set_tolerances(self):
        """This step's convergence tolerances [m/s]: tol_v of the velocity sweeps' largest
        change, tol_w of the overlap the position sweeps leave per step (half of
        overlap_tolerance of the smallest diameter per step: a position sweep's residual
        is the largest overlap it met, update_from's ``violation``; and the overlap above
        which Rules.position_extension's sweeps run, solver.overlap_left); and sweep caps
        (cap_v, cap_w; plain_v, plain_w: the plain sweeps that end them) (kernel top
        level)."""
        self.tol_v[None] = ti.static(self.rules.contact_tolerance) * self.impact_speed()
        self.tol_w[None] = 5 * self.tol_len[None] / self.params.h[None]   # (tol_len: 1/10)
        self.set_cap(self.cap_v, self.plain_v, self.full_v[None])
        self.set_cap(self.cap_w, self.plain_w, self.full_w[None])

    @ti.func
    def set_cap(self, cap: ti.template(), plain: ti.template(), full):
        """This step's sweep cap and plain sweeps of a solve capped at ``full`` sweeps:
        ``full`` and Rules.plain_sweeps, or with Rules.step_scaled_sweeps both scaled by
        the step's length over a quiet bed's step h_q = (contact_margin - 1) D /
        impact speed (the bound substeps put on a held bed's step; quiet_len holds
        (contact_margin - 1) D [m], 0 where unknown: the full caps): ceil(full h / h_q), within
        [Rules.min_scaled_sweeps, full], and the plain sweeps in proportion (at least
        one where plain_sweeps > 0). A sequence of short steps then runs about the
        sweeps per simulated second of quiet ones, each warm-started from the last; a
        cold solve (the first of a Simulation, no has_last_step; or Rules.warm_start off) has
        no last step to start from and keeps the full caps."""
        cap[None] = full
        plain[None] = self.plain_sweeps[None]
        if ti.static(self.rules.step_scaled_sweeps and self.rules.warm_start):
            share = ti.cast(1, self.real)      # quiet_len 0 (unknown), or cold: full caps
            if self.quiet_len[None] > 0 and self.has_last_step():
                share = ti.min(self.params.h[None] * self.impact_speed() /
                               self.quiet_len[None], 1)
            low = ti.min(self.min_scaled[None], full)
            n = ti.min(ti.max(ti.cast(ti.ceil(full * share), ti.i32), low), full)
            cap[None] = n
            if self.plain_sweeps[None] > 0:
                plain[None] = ti.max(1, (self.plain_sweeps[None] * n + full - 1) // full)

    @ti.func
    def warm_start_serially(self):
        """Apply every row's warm-start impulse, colour by colour (one thread: colours
        share spheres; kernel top level)."""
        ti.loop_config(serialize=True)
        for colour in range(self.n_colours_f[None]):
            self.sweep_scheduled(colour, WARM, 1.0)

    @ti.func
    def sweep_relaxation(self, it, relaxed, cap, last):
        """(omega, plain) of sweep ``it`` (from 0) of a solve capped at ``cap`` sweeps:
        over-relaxed while ``relaxed`` and not among the ``last`` sweeps of the cap
        (set_cap), else plain (omega = 1; plain = 1)."""
        plain = plain_sweep(it, relaxed, cap, last)
        omega = ti.cast(1, self.real)
        if plain == 0:
            omega = self.omega_relax[None]
        return omega, plain

    @ti.func
    def after_sweep(self, it, relaxed, plain, cap, tol):
        """(it, relaxed, done) once sweep ``it`` left ``residual`` (next_sweep; within
        tolerance: not above ``tol`` [m/s])."""
        within = 1
        if self.residual[None] > tol:
            within = 0
        return next_sweep(it, relaxed, plain, cap, within)

    @ti.func
    def iterate_serially(self, mode: ti.template(), caps: ti.template(), last: ti.template(),
                         tol: ti.template()):
        """Sweeps over every colour until a plain sweep (omega 1) leaves the residual
        within tol[None], or caps[None] sweeps ran, the last last[None] of them plain
        (set_cap); returns the sweeps run."""
        it = 0
        cap = caps[None]
        relaxed = self.relax_on[None]
        done = 0
        while done == 0:
            omega, plain = self.sweep_relaxation(it, relaxed, cap, last[None])
            self.residual[None] = 0
            for colour in range(self.n_colours_f[None]):
                self.sweep_scheduled(colour, mode, omega)
            it, relaxed, done = self.after_sweep(it, relaxed, plain, cap, tol[None])
        return it

    @ti.func
    def begin_batched_sweep(self, first, cap: ti.template(), last: ti.template()):
        """Before a sweep of a batch (kernel top level, one serial task): the solve's
        counters reset if ``first``; unless the solve is done, this sweep's relaxation
        to batch_omega and the residual to 0."""
        ti.loop_config(serialize=True)
        for _ in range(1):
            if first != 0:
                self.batch_it[None] = 0
                self.batch_relaxed[None] = self.relax_on[None]
                self.batch_done[None] = 0
            if self.batch_done[None] == 0:
                omega, plain = self.sweep_relaxation(
                    self.batch_it[None], self.batch_relaxed[None], cap[None], last[None])
                self.batch_omega[None] = omega
                self.batch_plain[None] = plain
                self.residual[None] = 0

    @ti.func
    def end_batched_sweep(self, cap: ti.template(), tol: ti.template()):
        """After a sweep of a batch (one serial task): after_sweep on the batch's
        counters, unless the solve was already done."""
        ti.loop_config(serialize=True)
        for _ in range(1):
            if self.batch_done[None] == 0:
                it, relaxed, done = self.after_sweep(
                    self.batch_it[None], self.batch_relaxed[None], self.batch_plain[None],
                    cap[None], tol[None])
                self.batch_it[None] = it
                self.batch_relaxed[None] = relaxed
                self.batch_done[None] = done

    @ti.func
    def batched_sweep(self, first, mode: ti.template(), colours: ti.template(),
                      cap: ti.template(), last: ti.template(), tol: ti.template()):
        """One sweep of iterate_serially's solve, launched by the host several at a
        time before it waits (kernel top level): a serial task deciding the relaxation
        (the solve's counters reset if ``first``), a parallel task per colour (empty once
        the solve is done) and a serial task testing the residual. The same sweeps with
        the same relaxations as iterate_serially, so the same bits; the host waits once
        per batch (batch_result) instead of once per sweep."""
        self.begin_batched_sweep(first, cap, last)
        for colour in ti.static(range(colours)):
            self.sweep_colour(colour, mode, 1.0, True)
        self.end_batched_sweep(cap, tol)

    @ti.func
    def batch_result(self):
        """The sweeps a batched solve ran once it is done, else 0."""
        return self.batch_it[None] if self.batch_done[None] != 0 else 0
