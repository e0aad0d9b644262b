"""Friction rows of the contact solver (contacts/solver.py): Coulomb friction and rolling
resistance of each persistent contact, solved in the same projected Gauss–Seidel sweep
as its normal row, warm-started the same way (contacts/rows.py).

Each contact row s (normal n, accumulated normal impulse lambda_n) carries
- a tangential impulse lam_t (a vector in the contact's tangent plane: the two
  tangential rows of the contact in one), updated towards zero tangential contact
  velocity u_t (static friction): ``lam_t -= m_t u_t`` with the tangential effective
  mass m_t = 2/7 m_eff (contacts/friction.py), then clamped to the friction disc
  ``|lam_t| <= mu lambda_n`` (Coulomb; isotropic, so the result does not depend on a
  choice of tangent axes);
- with rolling friction mu_r, an angular impulse lam_r driving the relative spin
  ``w_a - w_b`` to zero, its rolling part (about the tangent plane) and its twisting
  part (about the normal) each clamped to ``mu_r r_eff lambda_n`` (r_eff = r_a r_b /
  (r_a + r_b), r_a on a wall; friction.py rolling_bounded): the torques of a rolling
  and a twisting resistance each bounded by mu_r r_eff times the normal force (Zhou et
  al. 1999's constant-torque model, in impulse form), as LAMMPS's rolling and twisting
  models and Project Chrono's rolling and spinning friction with equal coefficients.
  Twisting is resisted too: otherwise a grain spinning about the vertical on a floor,
  which no tangential force slows, would spin for ever.
Friction is solved before the normal row in each sweep (Box2D's order: the normal row,
which prevents overlap, has the last word).

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti

from .friction import (TANGENTIAL_MASS, clamped, contact_velocity, rolling_bounded,
                       spin_change, tangential_part)

#: wall rows 0..5 are the box's walls (2 x axis + side), from 6 on geometry objects
GEOMETRY_ROWS = 6


@ti.func
def idle(impulse):
    """Every component of the vector impulse is zero (either sign)."""
    return impulse[0] == 0 and impulse[1] == 0 and impulse[2] == 0


class FrictionRows:
    """Tangential and rolling updates of one row, their coefficients and limits."""

    @ti.func
    def row_friction(self, s):
        """Friction coefficient of row s (kept by keep_row_coefficients)."""
        return self.row_mu[s]

    @ti.func
    def rolling_limit(self, s):
        """mu_r r_eff lambda_n of row s [N m s] (mu_r r_eff kept by
        keep_row_coefficients)."""
        return self.row_roll[s] * self.lam[s]

    @ti.func
    def keep_row_coefficients(self, s):
        """Keep row s's friction coefficient (the pair value of the two spheres'
        materials, the wall value, or the geometry object's: params.geo column 13) and,
        with rolling friction, mu_r r_eff [m] (r_eff = r_a r_b / (r_a + r_b); on a
        wall r_a and sphere a's material's mu_r), so that no row update divides or
        looks them up."""
        a = self.row_a[s]
        b = self.row_b[s]
        ma = self.state.material_of(a)
        mu = ti.cast(0, self.real)
        if b >= 0:
            mu = self.params.friction_of(ma, self.state.material_of(b))
        else:
            wall = -1 - b
            mu = self.params.mu_wall[None]
            if wall >= GEOMETRY_ROWS:
                mu = self.params.geo[wall - GEOMETRY_ROWS, 13]
        self.row_mu[s] = mu
        if ti.static(self.f.rolling):
            r = self.state.rad(a)
            mb = ma
            if b >= 0:
                rb = self.state.rad(b)
                r = r * rb / (r + rb)
                mb = self.state.material_of(b)
            self.row_roll[s] = self.params.rolling_of(ma, mb) * r

    @ti.func
    def push_tangent(self, a, b, n, impulse):
        """Apply a tangential impulse [N s] on a at the contact (-impulse on b); plain
        stores, not atomics (GaussSeidel.push)."""
        v, omega = ti.static(self.state.v, self.state.omega)
        v[a] = v[a] + impulse * self.inv_mass(a)
        omega[a] = omega[a] + spin_change(self.state.rad(a), self.state.inv_inertia_of(a),
                                          n, impulse)
        if b >= 0:
            v[b] = v[b] - impulse * self.inv_mass(b)
            omega[b] = omega[b] + spin_change(self.state.rad(b),
                                              self.state.inv_inertia_of(b), n, impulse)

    @ti.func
    def push_rolling(self, a, b, impulse):
        """Apply an angular impulse [N m s] on a (-impulse on b); plain stores."""
        omega = ti.static(self.state.omega)
        omega[a] = omega[a] + impulse * self.state.inv_inertia_of(a)
        if b >= 0:
            omega[b] = omega[b] - impulse * self.state.inv_inertia_of(b)

    @ti.func
    def friction_row(self, s):
        """One update of row s's tangential impulse; returns the change of the
        tangential contact velocity it made [m/s]. A row whose disc has shrunk to a
        point (mu lambda_n = 0: a speculative row, a contact the normal row has opened,
        mu = 0) and that holds no tangential impulse is left as it is: the update
        would clamp it to zero again and change nothing but, at most, the sign of an
        exact zero (idle)."""
        old = self.lam_t[s]
        limit = self.row_friction(s) * self.lam[s]
        out = ti.cast(0, self.real)
        if limit > 0 or not idle(old):
            a = self.row_a[s]
            b = self.row_b[s]
            n = self.normal[s]
            vb = ti.Vector.zero(self.real, 3)
            wb = ti.Vector.zero(self.real, 3)
            rb = ti.cast(0, self.real)
            if b >= 0:
                vb = self.state.v[b]
                wb = self.state.omega[b]
                rb = self.state.rad(b)
            ut = tangential_part(contact_velocity(self.state.v[a], vb, self.state.omega[a],
                                                  wb, self.state.rad(a), rb, n), n)
            mt = ti.static(TANGENTIAL_MASS) * self.meff[s]
            new = clamped(old - mt * ut, limit)
            self.lam_t[s] = new
            self.push_tangent(a, b, n, new - old)
            out = (new - old).norm() / mt
        return out

    @ti.func
    def rolling_row(self, s):
        """One update of row s's rolling (and twisting) impulse; returns the change of
        the relative spin times r_a it made [m/s]. Idle, as friction_row, where its
        bound is zero and it holds no impulse."""
        old = self.lam_r[s]
        limit = self.rolling_limit(s)
        out = ti.cast(0, self.real)
        if limit > 0 or not idle(old):
            a = self.row_a[s]
            b = self.row_b[s]
            wrel = self.state.omega[a]
            k = self.state.inv_inertia_of(a)
            if b >= 0:
                wrel = wrel - self.state.omega[b]
                k += self.state.inv_inertia_of(b)
            new = rolling_bounded(old - wrel / k, self.normal[s], limit)
            self.lam_r[s] = new
            self.push_rolling(a, b, new - old)
            out = (new - old).norm() * k * self.state.rad(a)
        return out

    @ti.func
    def warm_friction(self, s):
        """Apply row s's warm-start tangential and rolling impulses."""
        a = self.row_a[s]
        b = self.row_b[s]
        self.push_tangent(a, b, self.normal[s], self.lam_t[s])
        if ti.static(self.f.rolling):
            self.push_rolling(a, b, self.lam_r[s])

    @ti.func
    def solve_friction(self, s):
        """Rolling then tangential update of row s (before its normal update); returns
        the largest velocity change [m/s]."""
        out = ti.cast(0, self.real)
        if ti.static(self.f.rolling):
            out = self.rolling_row(s)
        return ti.max(out, self.friction_row(s))
