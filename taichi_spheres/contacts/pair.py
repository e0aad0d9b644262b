"""The pair rule: geometry of a pair, when it is an impact to resolve, and the collision.

Physics (docs/design.md; the seed paper's eqs. (8)-(14) written without angles):
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

A mixin of :class:`taichi_spheres.contacts.Contacts` (its fields and options).
"""

import taichi as ti



class PairRule:
    """Pair geometry (minimum image), the approach test, the contact time and the
    collision of one pair (:meth:`collide`)."""

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
        within about 66 degrees of vertical (rules.support_cos), with a supported sphere
        below (on the floor, or itself stopped by a supported sphere in this step) and an
        unsupported one
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
            dvi, dvj = self.velocity_change(i, j, n, un, u, e, self.slow_contact(i, j, e, un), s)
            self.apply_collision(i, j, dvi, dvj, s, rc)

    @ti.func
    def slow_contact(self, i, j, e, un):
        """Whether the collapse rule or the rest rule makes this collision (normal
        approach speed -un [m/s]) perfectly inelastic in the normal direction. Collapse:
        from a sphere's rules.collapse_hits-th collision in one step on (inelastic pairs
        only; e < 1 checked here too: compiled in with e = 1 it must not change the
        physics), so that dense clusters cannot collide without end within a step.
        Rest: slower than the rest speed, for a resting contact (see resting())."""
        rest = False
        if ti.static(not self.f.elastic):
            rest = e < 1 and ti.max(self.state.hits[i], self.state.hits[j]) >= \
                ti.static(self.rules.collapse_hits - 1)
        if ti.static(self.f.rest_rule):
            rest = rest or (-un < self.params.rest_speed[None] and self.resting(i, j))
        return rest

    @ti.func
    def pair_weights(self, i, j):
        """(w_i, w_j, m_eff): inverse-mass weights m_j/(m_i+m_j), m_i/(m_i+m_j) and the
        reduced mass [kg] (1/2, 1/2 and m/2 for equal masses)."""
        wi = ti.cast(0.5, self.real)
        wj = ti.cast(0.5, self.real)
        meff = self.half_m0[None]
        if ti.static(not self.f.equal_masses):
            imi = self.state.inv_mass_of(i)
            imj = self.state.inv_mass_of(j)
            wi = imi / (imi + imj)
            wj = imj / (imi + imj)
            meff = 1 / (imi + imj)
        return wi, wj, meff

    @ti.func
    def velocity_change(self, i, j, n, un, u, e, rest, s):
        """(dv_i, dv_j) [m/s] of the collision of (i, j) with normal n, normal relative
        speed un < 0 and relative velocity u, restitution e; ``rest``: perfectly
        inelastic (normal), or the supported stop (supports). Books the energy removed
        per cause (vals E_PAIRS, E_REST) and the rule's firing (count RESTED)."""
        wi, wj, meff = self.pair_weights(i, j)
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
                ti.atomic_add(self.params.energy_rest_rule[None], 0.5 * meff * un * un)
                ti.atomic_add(self.params.rest_collisions[None], 1)
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
                    ti.atomic_add(self.params.energy_pair_restitution[None], loss)
        return dvi, dvj

    @ti.func
    def apply_collision(self, i, j, dvi, dvj, s, rc):
        """Apply velocity changes dv_i, dv_j [m/s] at contact, s [s] ago, and carry them
        forward; mark and count both spheres, book the virial r_ij . dp_i (rc: the
        contact separation, j to i [m]), the pair count, the largest speed and move."""
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
        ti.atomic_add(self.params.virial[None], rc.dot(dvi) * self.state.mass_of(i))
        ti.atomic_add(self.params.pair_collisions[None], 1)
        ti.atomic_max(self.params.vmax2[None], ti.max(self.state.v[i].norm_sqr(),
                                                      self.state.v[j].norm_sqr()))
        ti.atomic_max(self.params.moved[None], ti.max(self.state.moved[i], self.state.moved[j]))

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
                ti.atomic_add(self.params.energy_rest_rule[None], -self.state.mass_of(upper) * gain)
                ti.atomic_add(self.params.rest_collisions[None], 1)
                ti.atomic_add(self.params.supported_collisions[None], 1)
        return done, dvi, dvj

    @ti.func
    def mark_touched(self, i):
        if ti.atomic_or(self.marked[self.grid.slot[i]], 1) == 0:
            self.touched[ti.atomic_add(self.n_touched[None], 1)] = i
