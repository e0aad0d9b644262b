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

from .friction import (contact_velocity, rolling_impulse, rolling_loss, spin_change,
                       tangential_part, walton_impulse)


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
    def approaching_pair(self, i, j, dd, du, uu, ss):
        """approaching(), and with the contact solver (Features.contacts) faster than
        the pair's impact speed (walls.Motion.pair_impact_speed: 0 unless one of the
        two bears load): a slower approach is a persistent contact, solved by the
        contact solver instead of rewound."""
        out = self.approaching(dd, du, uu, ss)
        if ti.static(self.f.contacts):
            if out:
                vimp = self.motion.pair_impact_speed(i, j)
                out = du * du > vimp * vimp * dd
        return out

    @ti.func
    def impact_speed(self):
        """Approach speed from which a pair is an impact [m/s] (walls.Motion.impact_speed)."""
        return self.motion.impact_speed()

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
                if self.approaching_pair(i, j, dc.norm_sqr(), dc.dot(u), uu, ss):
                    out = s
        return out

    @ti.func
    def collide(self, i, j, s):
        """Rewind i, j by s to contact, apply the restitution impulse, carry forward.

        Restitution (see the module docstring): "normal" u_n' = -e u_n with the
        tangential relative velocity unchanged; "smid" (Features.smid) the seed's rule
        after Smid (2007), u' = e (u - 2 u_n n): the whole relative velocity of the
        elastic result scaled by e about the centre of mass. Collapse rule
        (slow_contact): perfectly inelastic in the normal direction. Energy removed is
        booked per cause (params.energy_pair_restitution, energy_collapse)."""
        d, sigma = self.separation(i, j)
        u = self.rel_velocity(i, j)
        rc = d - u * s
        n = rc.normalized()
        un = u.dot(n)
        if un < 0:
            e = ti.cast(1, self.real)
            if ti.static(not self.f.elastic):
                e = self.params.restitution_of(self.state.material_of(i),
                                               self.state.material_of(j))
            collapse = self.collapsing(i, j, e)
            dvi, dvj = self.velocity_change(i, j, n, un, u, e, collapse)
            if ti.static(self.f.friction):
                e_n = e
                if collapse:
                    e_n = 0
                dvi, dvj = self.impact_friction(i, j, n, u, -(1 + e_n) * un, dvi, dvj)
            self.apply_collision(i, j, dvi, dvj, s, rc)

    @ti.func
    def impact_friction(self, i, j, n, u, jn_speed, dvi, dvj):
        """Add the tangential impulse of Walton's model (contacts/friction.py) to the
        velocity changes dv_i, dv_j [m/s] of the impact of (i, j) with normal n and
        relative velocity u before it, whose normal impulse is m_eff x jn_speed [N s];
        change both spins and book the energy the friction took
        (params.energy_pair_restitution)."""
        wi, wj, meff = self.pair_weights(i, j)
        ri = self.state.rad(i)
        rj = self.state.rad(j)
        ut = tangential_part(contact_velocity(u, u * 0, self.state.omega[i], self.state.omega[j],
                                              ri, rj, n), n)
        mu = self.params.friction_of(self.state.material_of(i), self.state.material_of(j))
        p = walton_impulse(ut, meff * jn_speed, meff, mu, self.params.beta_max[None])
        self.state.omega[i] += spin_change(ri, self.state.inv_inertia_of(i), n, p)
        self.state.omega[j] += spin_change(rj, self.state.inv_inertia_of(j), n, p)
        after = ut + ti.cast(3.5, self.real) / meff * p
        ti.atomic_add(self.params.energy_pair_restitution[None],
                      ti.cast(1 / 7, self.real) * meff * (ut.norm_sqr() - after.norm_sqr()))
        if ti.static(self.f.rolling):
            self.impact_rolling(i, j, ri, rj, n, meff * jn_speed)
        return dvi + wi / meff * p, dvj - wj / meff * p

    @ti.func
    def impact_rolling(self, i, j, ri, rj, n, jn):
        """Rolling resistance of the impact of (i, j) with normal n and normal impulse jn [N s]
        (contacts/friction.py): both spins change, the energy goes to
        params.energy_pair_restitution."""
        inv_i = self.state.inv_inertia_of(i)
        inv_j = self.state.inv_inertia_of(j)
        rel = self.state.omega[i] - self.state.omega[j]
        mu_r = self.params.rolling_of(self.state.material_of(i), self.state.material_of(j))
        p = rolling_impulse(rel, inv_i, inv_j, n, mu_r * ri * rj / (ri + rj) * jn)
        self.state.omega[i] += inv_i * p
        self.state.omega[j] -= inv_j * p
        ti.atomic_add(self.params.energy_pair_restitution[None],
                      rolling_loss(rel, inv_i, inv_j, p))

    @ti.func
    def collapsing(self, i, j, e):
        """Whether the collapse rule makes this collision perfectly inelastic in the
        normal direction: from a sphere's rules.collapse_hits-th collision in one step
        on (inelastic pairs only; e < 1 checked here too: compiled in with e = 1 it must
        not change the physics), so that dense clusters cannot collide without end
        within a step."""
        out = False
        if ti.static(not self.f.elastic):
            out = e < 1 and ti.max(self.state.hits[i], self.state.hits[j]) >= \
                ti.static(self.rules.collapse_hits - 1)
        return out

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
    def velocity_change(self, i, j, n, un, u, e, collapse):
        """(dv_i, dv_j) [m/s] of the collision of (i, j) with normal n, normal relative
        speed un < 0 and relative velocity u, restitution e; ``collapse``: perfectly
        inelastic (normal). Books the energy removed per cause
        (params.energy_pair_restitution, energy_collapse, collapse_collisions)."""
        wi, wj, meff = self.pair_weights(i, j)
        dvi = ti.Vector.zero(self.real, 3)
        dvj = ti.Vector.zero(self.real, 3)
        if collapse:
            dvi = -un * wi * n
            dvj = un * wj * n
            ti.atomic_add(self.params.energy_collapse[None], 0.5 * meff * un * un)
            ti.atomic_add(self.params.collapse_collisions[None], 1)
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
    def mark_touched(self, i):
        if ti.atomic_or(self.marked[self.grid.slot[i]], 1) == 0:
            self.touched[ti.atomic_add(self.n_touched[None], 1)] = i
