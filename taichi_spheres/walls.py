"""Free flight and walls (step stage 1): exact ballistic drift, exact wall rewind.

Free flight (docs/design.md, "Physics"): ``x += v h + g h^2/2``, ``v += g h``.

Walls: each axis moves independently, so a sphere that ends a step past a wall on
axis ``a`` is rewound along its own ballistic path to the contact time: with
``d < 0`` the signed distance past the contact plane (inside positive), ``w`` the
velocity and ``g`` the acceleration along the inward normal, the time since
contact ``s`` is the smallest root of ``g/2 s^2 - w s + d = 0`` at which the
sphere was moving into the wall (``w - g s < 0``). The normal velocity at contact
is reversed and scaled by the wall restitution, and the sphere is carried forward
by ``s`` on its new path. A sphere whose penetration is not explained by a
crossing on its current ballistic path (a pair collision carried it there, or it
rests on the wall under gravity) is put back: without gravity on that axis it is
mirrored into the box and its inward velocity reflected; with gravity it is placed
on the wall and the potential energy of that lift is taken from its normal kinetic
energy, so the total never grows (counted in ``stats['wall_rests']``). A sphere
that re-crosses within the same step (small e under gravity) bounces again, up to
``Rules.max_wall_bounces`` times (taichi_spheres/config.py); if it is still past the wall then, it is put on the
wall and its velocity into the wall is zeroed — a "wall rest" that never adds
kinetic energy, counted in ``stats['wall_rests']``.
"""

import taichi as ti

from .config import DEFAULT, Tuning
from .contacts.friction import (contact_velocity, rolling_impulse, rolling_loss, spin_change,
                                tangential_part, walton_impulse)
from .params import StepParams
from .state import Features, SphereState
from .surfaces import Surfaces


@ti.data_oriented
class Motion(Surfaces):
    """Drift and wall kernels over a :class:`SphereState` (shapes: see SphereState)."""

    def __init__(self, state: SphereState, params: StepParams, features: Features,
                 serial_light: bool, tuning: Tuning = DEFAULT):
        self.state = state
        self.params = params
        self.f = features
        self.real = state.real
        self.serial_light = serial_light
        self.max_bounces = tuning.physics.max_wall_bounces
        self.substeps = tuning.physics.substeps and features.contacts

        # hot kernels as plain closures: a data_oriented method kernel pays ~40 us of
        # Python dispatch per launch for its `self` template argument

        @ti.kernel
        def drift():
            self._drift_body()

        self.drift = drift

        @ti.kernel
        def measure_vmax():
            self._measure_vmax_body()

        self.measure_vmax = measure_vmax

    @ti.func
    def _contact_time(self, d, w, acc, accelerated: ti.template()):
        """Time since wall contact s >= 0 (or -1 if none) for inward distance d < 0,
        inward velocity w and inward acceleration acc: root of acc/2 s^2 - w s + d = 0
        with w - acc s < 0, computed without cancellation."""
        s = ti.cast(-1, self.real)
        if ti.static(not accelerated):
            if w < 0:
                s = d / w
        elif acc == 0:
            if w < 0:
                s = d / w
        else:
            a2 = acc * ti.cast(0.5, self.real)
            b = -w
            disc = b * b - 4 * a2 * d
            if disc >= 0:
                sq = ti.sqrt(disc)
                q = -ti.cast(0.5, self.real) * (b + (sq if b >= 0 else -sq))
                r1 = ti.cast(-1, self.real)
                r2 = ti.cast(-1, self.real)
                if q != 0:
                    r1 = q / a2
                    r2 = d / q
                for root in ti.static((0, 1)):
                    r = r1 if root == 0 else r2
                    if r >= 0 and w - acc * r < 0 and (s < 0 or r < s):
                        s = r
        return s

    @ti.func
    def count_in_sinks(self, i):
        """Count sphere i in params.in_sinks if its centre is in a sink region."""
        if self.params.in_a_sink(self.state.x[i]):
            ti.atomic_add(self.params.in_sinks[None], 1)

    @ti.func
    def contain(self, i):
        """walls_and_wrap, then the geometry objects (surfaces.py) for sphere i."""
        self.walls_and_wrap(i)
        if ti.static(self.f.geometry):
            self.geometry_impacts(i)

    @ti.func
    def walls_and_wrap(self, i):
        """Bring sphere i back inside the box: wrap periodic axes, bounce off walls (see
        the module docstring)."""
        x = self.wrap_periodic(self.state.x[i])
        v = self.state.v[i]
        if ti.static(self.f.walls):
            r = self.state.rad(i)
            h = self.params.h[None]
            moved = ti.cast(0, self.real)
            e_w = ti.cast(1, self.real)
            if ti.static(not self.f.elastic_walls):
                e_w = self.params.e_wall[None]
            for a in ti.static(range(3)):
                if ti.static(self.f.wall_axes[a]):
                    x, v, moved = self.walls_on_axis(i, a, x, v, moved, r, h, e_w)
            self.state.moved[i] += moved
        self.state.x[i] = x
        self.state.v[i] = v

    @ti.func
    def wrap_periodic(self, x):
        """Position x [m] wrapped into the box on periodic axes (one shift: positions
        never move more than a box length in a step)."""
        for a in ti.static(range(3)):
            if ti.static(not self.f.wall_axes[a]):
                if x[a] < self.params.lo[None][a]:
                    x[a] += self.params.size[None][a]
                elif x[a] >= self.params.hi[None][a]:
                    x[a] -= self.params.size[None][a]
        return x

    @ti.func
    def walls_on_axis(self, i, a: ti.template(), x, v, moved, r, h, e_w):
        """The walls of axis a for sphere i of radius r [m] at x, v: bounce while it is
        past one (up to max_bounces times, then rest on it); returns x, v and the bound
        ``moved`` [m] grown by the moves. With the contact solver, a slow contact is
        left to it (module docstring)."""
        g_a = ti.cast(0, self.real)
        if ti.static(self.f.gravity_axes[a]):
            g_a = self.params.gravity[None][a]
        lo_c = self.params.lo[None][a] + r
        hi_c = self.params.hi[None][a] - r
        for bounce in range(ti.static(self.max_bounces + 1)):
            side = 0
            d = ti.cast(0, self.real)
            if x[a] < lo_c:
                side = -1
                d = x[a] - lo_c
            elif x[a] > hi_c:
                side = 1
                d = hi_c - x[a]
            if side == 0:
                break
            w = v[a] * side * -1
            acc = g_a * side * -1
            s = self._contact_time(d, w, acc, self.f.gravity_axes[a])
            if ti.static(self.f.contacts):
                if self.persistent(i, w, acc, s):
                    break
            last = bounce == ti.static(self.max_bounces)
            xa = lo_c
            if side > 0:
                xa = hi_c
            va = v[a]
            if not last and s >= 0 and s <= 2 * h:
                xa, va, moved = self.bounce(i, d, w, acc, s, side, lo_c, hi_c, e_w, moved)
                if ti.static(self.f.friction):
                    # normal speed change at contact: rebound + arrival speed
                    jn = (va * side * -1 - acc * s) - (w - acc * s)
                    x, v, moved = self.wall_friction(i, a, side, x, v, s, jn, r, moved)
            elif not last:
                xa, va, moved = self.put_back(i, d, w, acc, side, lo_c, hi_c, e_w, moved, a)
            else:
                # still past the wall after max_bounces bounces: rest on it
                if side < 0:
                    va = ti.max(v[a], 0)
                else:
                    va = ti.min(v[a], 0)
                moved += -d
                ti.atomic_add(self.params.wall_rests[None], 1)
            x[a] = xa
            v[a] = va
            if last:
                break
        return x, v, moved

    @ti.func
    def wall_friction(self, i, a: ti.template(), side, x, v, s, jn, r, moved):
        """Tangential impulse of Walton's model (contacts/friction.py) for sphere i (radius
        r [m]) that hit the wall of axis a (side -1: lo, 1: hi) s [s] ago with a normal
        speed change jn [m/s] (its normal impulse / m): applied at contact and carried
        forward (x += dv s), spin changed; returns x, v and moved. Books the energy
        the friction took (params.energy_wall_restitution)."""
        n = ti.Vector.zero(self.real, 3)
        n[a] = -ti.cast(side, self.real)
        vc = v
        if ti.static(self.f.gravity):
            vc = v - self.params.gravity[None] * s
        ut = tangential_part(contact_velocity(vc, vc * 0, self.state.omega[i], vc * 0, r, r, n), n)
        m = self.state.mass_of(i)
        p = walton_impulse(ut, m * jn, m, self.params.mu_wall[None], self.params.beta_max[None])
        dv = p / m
        self.state.omega[i] += spin_change(r, self.state.inv_inertia_of(i), n, p)
        after = ut + ti.cast(3.5, self.real) * dv
        ti.atomic_add(self.params.energy_wall_restitution[None],
                      ti.cast(1 / 7, self.real) * m * (ut.norm_sqr() - after.norm_sqr()))
        if ti.static(self.f.rolling):
            self.surface_rolling(i, r, n, m * jn)
        return x + dv * s, v + dv, moved + dv.norm() * s

    @ti.func
    def surface_rolling(self, i, r, n, jn):
        """Rolling resistance of an impact of sphere i (radius r [m]) on a wall or
        geometry surface with normal n and normal impulse jn [N s] (contacts/friction.py; mu_r: the
        sphere's material's); the energy goes to params.energy_wall_restitution."""
        inv_i = self.state.inv_inertia_of(i)
        w = self.state.omega[i]
        m = self.state.material_of(i)
        p = rolling_impulse(w, inv_i, ti.cast(0, self.real), n,
                            self.params.rolling_of(m, m) * r * jn)
        self.state.omega[i] += inv_i * p
        ti.atomic_add(self.params.energy_wall_restitution[None],
                      rolling_loss(w, inv_i, ti.cast(0, self.real), p))

    @ti.func
    def persistent(self, i, w, acc, s):
        """A sphere past a wall, moving into it at w (inward speed, < 0 into the wall)
        with inward acceleration acc, which crossed it s ago (-1: not on its current
        path), is a persistent contact: it met the wall slower than the impact speed."""
        wc = w
        if s >= 0:
            wc = w - acc * s
        return -wc < self.wall_impact_speed(i, acc)

    @ti.func
    def wall_impact_speed(self, i, acc):
        """Impact speed of sphere i on a wall with inward acceleration acc [m/s^2]: the
        impact speed where gravity presses spheres into the wall (acc < 0, a floor) or
        where the sphere bears load (state.loaded: a contact row of it carried an
        impulse in the last step, as in a pile against a side wall); else 0 (a sphere
        in flight keeps its restitution on side walls and ceilings)."""
        out = self.impact_speed()
        if acc >= 0 and self.state.loaded[i] == 0:
            out = ti.cast(0, self.real)
        return out

    @ti.func
    def pair_impact_speed(self, i, j):
        """Impact speed of pair (i, j): the impact speed if either sphere bears load
        (state.loaded), else 0 (two spheres in flight collide exactly whatever their
        speed)."""
        out = self.impact_speed()
        if self.state.loaded[i] == 0 and self.state.loaded[j] == 0:
            out = ti.cast(0, self.real)
        return out

    @ti.func
    def impact_speed(self):
        """Approach speed from which a pair or wall contact is an impact [m/s]
        (params.rest_speed: simulation.rest_speed_for); slower ones are persistent
        contacts (contacts/solver.py)."""
        return self.params.rest_speed[None]

    @ti.func
    def bounce(self, i, d, w, acc, s, side, lo_c, hi_c, e_w, moved):
        """A crossing s [s] ago on the current path (d < 0 past the contact plane, w and
        acc inward speed and acceleration): rebound at contact and carry forward;
        returns the new coordinate [m], velocity component [m/s] and moved [m]."""
        wc = w - acc * s
        wn = self.rebound(i, -wc, e_w)
        dn = wn * s + ti.cast(0.5, self.real) * acc * s * s
        xa = lo_c + dn
        if side > 0:
            xa = hi_c - dn
        va = (wn + acc * s) * side * -1
        moved += (wn - wc) * s
        ti.atomic_add(self.params.wall_collisions[None], 1)
        self.count_hit(i)
        return xa, va, moved

    @ti.func
    def put_back(self, i, d, w, acc, side, lo_c, hi_c, e_w, moved, a: ti.template()):
        """Past the wall without a crossing on its current path (a pair collision
        carried it there, or it rests on the wall): without gravity on the axis mirror
        it into the box and reflect (energy exact for e = 1); with gravity put it on the
        wall and pay the potential energy of the lift -acc d out of its normal kinetic
        energy, so energy never grows (a sphere resting under gravity stays at rest).
        Returns the new coordinate [m], velocity component [m/s] and moved [m]."""
        mirror = True
        if ti.static(self.f.gravity_axes[a]):
            mirror = acc == 0
        xa = lo_c
        if side > 0:
            xa = hi_c
        wn = w
        if mirror:
            if w < 0:
                wn = self.rebound(i, -w, e_w)
            xa = lo_c - d
            if side > 0:
                xa = hi_c + d
            moved += -2 * d
            ti.atomic_add(self.params.wall_collisions[None], 1)
            self.count_hit(i)
        else:
            w2 = ti.max(w * w - 2 * acc * d, 0)
            wn = ti.sqrt(w2)
            if w < 0:
                wn = self.rebound(i, wn, e_w)
            moved += -d
            ti.atomic_add(self.params.wall_rests[None], 1)
        va = wn * side * -1
        return xa, va, moved

    @ti.func
    def rebound(self, i, speed, e_w):
        """Outward normal speed after sphere i hits a wall at normal speed ``speed`` >= 0
        [m/s]: e_w x speed. Books the kinetic energy removed
        (params.energy_wall_restitution)."""
        out = e_w * speed
        if ti.static(not self.f.elastic_walls):
            ti.atomic_add(self.params.energy_wall_restitution[None], ti.cast(0.5, self.real) * self.state.mass_of(i) * (speed * speed - out * out))
        return out

    @ti.func
    def count_hit(self, i):
        """One more collision of sphere i in this step (counts spheres with several,
        and with Rules.substeps spheres that had a contact row: params.near_hits)."""
        if ti.atomic_add(self.state.hits[i], 1) == 1:
            ti.atomic_add(self.params.multi_collision_spheres[None], 1)
        if ti.static(self.substeps):
            if self.state.near[i] != 0:
                ti.atomic_add(self.params.near_hits[None], 1)

    @ti.func
    def _drift_body(self):
        """Advance every sphere by h on its exact ballistic path, then apply walls.

        Resets the per-step counters; records max |v|^2 for the next step size.
        """
        self.params.reset_step()
        ti.loop_config(serialize=ti.static(self.serial_light))
        for i in range(self.state.n_spheres[None]):
            h = self.params.h[None]
            self.state.hits[i] = 0
            if ti.static(self.f.gravity):
                grav = self.params.gravity[None]
                self.state.x[i] += self.state.v[i] * h + ti.cast(0.5, self.real) * grav * h * h
                self.state.v[i] += grav * h
            else:
                self.state.x[i] += self.state.v[i] * h
            self.contain(i)
            if ti.static(self.f.sinks):
                self.count_in_sinks(i)
            ti.atomic_max(self.params.vmax2[None], self.state.v[i].norm_sqr())

    @ti.func
    def _measure_vmax_body(self):
        """params.vmax2 = max |v|^2 over all spheres [m^2/s^2]."""
        self.params.vmax2[None] = 0
        for i in range(self.state.n_spheres[None]):
            ti.atomic_max(self.params.vmax2[None], self.state.v[i].norm_sqr())
