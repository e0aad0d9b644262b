"""Shock propagation: a last pass of the contact solver over its rows, from the
floor up, that treats the lower sphere of each pair as immovable (Erleben 2007,
"Velocity-based shock propagation for multibody dynamics animation", ACM TOG 26(2);
Guendelman, Bridson & Fedkiw 2003). Rules.shock_propagation switches it on.

Projected Gauss–Seidel needs many sweeps where the contact network is badly
conditioned: a heavy sphere on light ones (a mass ratio of 10^3 needs ~10^3 times
more sweeps than equal masses), a tall column or a deep bed. What the sweeps leave
unsolved makes spheres sink into each other. The pass removes exactly that: rows in
order of the height of their contact point (along gravity), each pushing only its
upper sphere (or the sphere of a wall row) so that the row's approach is no faster
than its target, and never pulling. A sphere is pushed only while it moves into its
support, and at most until it stops doing so (its kinetic energy never grows); the
lower sphere takes no reaction, so the pass bounds the sinking the sweeps left, it
does not solve the contacts: the sweeps still carry the loads. Where the sweeps
converged (every row within the velocity tolerance) it changes nothing.

Order: rows are counted into height bins (as many bins as rows) and taken bin by
bin, in row order inside a bin; the pass runs serially (one thread), so the result
is the same for any thread count.

A mixin of :class:`taichi_spheres.contacts.solver.ContactSolver` (its fields).
"""

import taichi as ti


def shock_compiled(features, rules) -> bool:
    """Whether a scene with ``features`` (state.Features) runs the pass under ``rules``
    (config.Rules): "on", or "auto" where the masses differ; never without gravity or
    where gravity points along a periodic axis (no floor to propagate from)."""
    floors = features.gravity and all(w for g, w in zip(features.gravity_axes,
                                                        features.wall_axes) if g)
    mode = rules.shock_propagation
    return floors and (mode == "on" or (mode == "auto" and not features.equal_masses))


class ShockPropagation:
    """The height order of the rows and the one-sided pass over them."""

    def _allocate_shock(self):
        """shock_key, shock_order: (K,) i32 — height bin of each row, rows by bin;
        shock_start: (K + 1,) i32 — places in shock_order: each bin's first after the
        prefix sum, its end after the rows are placed."""
        k = self.capacity
        self.shock_key = ti.field(ti.i32, shape=k)
        self.shock_order = ti.field(ti.i32, shape=k)
        self.shock_start = ti.field(ti.i32, shape=k + 1)

    @ti.func
    def height(self, p):
        """Height of point p along -gravity times |g| [m^2/s^2] (an order, not a
        length)."""
        return -self.params.gravity[None].dot(p)

    @ti.func
    def row_height(self, s):
        """height() of row s's contact point (normals point from b to a)."""
        a = self.row_a[s]
        return self.height(self.state.x[a] - self.state.rad(a) * self.normal[s])

    @ti.func
    def height_bounds(self, rows):
        """(lowest, highest) row height of the first ``rows`` rows (serial)."""
        lo = ti.cast(1e30, self.real)
        hi = ti.cast(-1e30, self.real)
        ti.loop_config(serialize=True)
        for s in range(rows):
            z = self.row_height(s)
            lo = ti.min(lo, z)
            hi = ti.max(hi, z)
        return lo, hi

    @ti.func
    def order_by_height(self, rows):
        """shock_order: the rows by height bin (counting sort, serial)."""
        lo, hi = self.height_bounds(rows)
        span = ti.max(hi - lo, ti.cast(1e-30, self.real))
        ti.loop_config(serialize=True)
        for b in range(rows + 1):
            self.shock_start[b] = 0
        ti.loop_config(serialize=True)
        for s in range(rows):
            key = ti.cast((self.row_height(s) - lo) / span * rows, ti.i32)
            key = ti.max(ti.min(key, rows - 1), 0)
            self.shock_key[s] = key
            self.shock_start[key + 1] += 1
        ti.loop_config(serialize=True)
        for b in range(rows):
            self.shock_start[b + 1] += self.shock_start[b]
        ti.loop_config(serialize=True)
        for s in range(rows):
            key = self.shock_key[s]
            self.shock_order[self.shock_start[key]] = s
            self.shock_start[key] += 1

    @ti.func
    def shock_row(self, s):
        """Row s with its lower sphere immovable: push the upper one (the sphere of a
        wall row) so that u_n >= target, if the sweeps left it short by more than the
        velocity tolerance, only while the upper sphere moves towards the lower one and
        at most until its own speed along the normal is zero. The push joins the row's
        impulse, so the next step's warm start carries it (with its reaction)."""
        v = ti.static(self.state.v)
        a = self.row_a[s]
        b = self.row_b[s]
        n = self.normal[s]
        up = a
        sign = ti.cast(1, self.real)
        rel = v[a]
        if b >= 0:
            rel = rel - v[b]
            if self.height(n) < 0:           # b above a (no periodic image needed)
                up = b
                sign = -1
        into = sign * v[up].dot(n)            # the upper sphere's speed away from the lower
        short = self.target[s] - rel.dot(n)   # the approach to remove [m/s]
        if short > self.tol_v[None] and into < 0:
            dv = ti.min(short, -into)
            v[up] = v[up] + sign * dv * n
            self.lam[s] += dv / self.inv_mass(up)

    @ti.func
    def shock_pass(self):
        """The pass over every row, lowest first (kernel top level, serial)."""
        rows = ti.min(self.n_rows[None], ti.static(self.capacity))
        self.order_by_height(rows)
        ti.loop_config(serialize=True)
        for t in range(rows):
            self.shock_row(self.shock_order[t])
