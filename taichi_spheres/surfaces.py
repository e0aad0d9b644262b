"""Static geometry besides the box (step stage 1, with the walls): planes with an
optional orifice, cylinders and cones (geometry.py describes them and packs each into
one row of params.geo).

Gap and normal of a sphere (centre x, radius r) to an object, as in geometry.py:
- plane (point p, unit normal n, orifice radius R_h or 0): with z = (x - p).n and rho
  the distance of x from the line through p along n, the gap is z - r (normal n)
  where rho >= R_h; over the orifice it is the distance to its rim circle minus r
  (z >= 0) or R_h - rho - r below the plane (the orifice's wall);
- cone (point p, unit axis a, radii R_0 at p and R_1 at length L; a cylinder has
  R_0 = R_1, and L < 0 for an infinite one): in the meridian plane (t along a, rho
  from the axis) the surface is the segment (0, R_0)-(L, R_1); the gap is the
  distance to it minus r, or the distance to the nearer end rim minus r beyond the
  segment. A finite cone or cylinder is a shell with two faces, the one on the side
  of the sphere's centre: a sphere that went round an open end (out of a hopper's
  outlet, then up against its outside; under a platform cone) meets the back face,
  with the normal towards it (had the back been solid, the gap would jump from the
  rim distance to minus the distance to the surface where the centre starts to
  project onto the segment, and the sphere would be pushed through the shell). A
  sphere pressed more than r through a face therefore comes out on the back. An
  infinite cylinder keeps its solid back (the outside for ``inside``). geometry.py's
  numpy gap with ``both_faces=True`` is this gap (the start check); without it, the
  front (``inside``) side's, where the package places spheres.
The normal points from the surface to the sphere's centre.

Impacts (exact rewind, as for the walls and pairs): a sphere that ends a step past a
surface but was clear of it at the step's start is rewound along its own ballistic
path ``x(s) = x - v s + g s^2/2`` to the contact time s, found by bisection to the
last bit of the step length (the gap along a ballistic path has no closed-form root
for a cone), collided there with the object's restitution and friction (Walton's
model, contacts/friction.py), and carried forward: ``x += dv s``, ``v += dv``. A
sphere approaching slower than the impact speed where gravity presses it into the
surface is a persistent contact, left to the contact solver's rows; without a
contact solver, a sphere found past a surface at the step's start is put back on it.

A mixin of :class:`taichi_spheres.walls.Motion` (its state, params and features).
"""

import taichi as ti

from .contacts.friction import contact_velocity, spin_change, tangential_part, walton_impulse

#: columns of a packed geometry row (geometry.py: PACKED_WIDTH)
KIND, POINT, AXIS, R0, R1, LENGTH, INSIDE, HOLE, RESTITUTION, FRICTION = 0, 1, 4, 7, 8, 9, 10, 11, 12, 13
PLANE = 0


class Surfaces:
    """Gap, normal and impacts of spheres on the geometry objects in params.geo."""

    @ti.func
    def geo_vector(self, k, col: ti.template()):
        """Columns col..col+2 of geometry row k as a vector."""
        return ti.Vector([self.params.geo[k, col], self.params.geo[k, col + 1],
                          self.params.geo[k, col + 2]])

    @ti.func
    def radial(self, d, a):
        """(rho, unit radial vector) of offset d from an axis of unit direction a (any
        unit vector perpendicular to a when d lies on the axis)."""
        rv = d - d.dot(a) * a
        rho = rv.norm()
        e = ti.Vector([a[1], -a[0], ti.cast(0, self.real)])
        if ti.abs(a[2]) > ti.cast(0.9, self.real):
            e = ti.Vector([ti.cast(0, self.real), a[2], -a[1]])
        e = e.normalized()
        if rho > 0:
            e = rv / rho
        return rho, e

    @ti.func
    def surface_gap(self, k, x, r):
        """(gap [m], unit normal from the surface to x) of a sphere at x of radius r and
        geometry object k (module docstring)."""
        gap = ti.cast(0, self.real)
        n = ti.Vector.zero(self.real, 3)
        if self.params.geo[k, KIND] == PLANE:
            gap, n = self.plane_gap(k, x, r)
        else:
            gap, n = self.cone_gap(k, x, r)
        return gap, n

    @ti.func
    def plane_gap(self, k, x, r):
        """surface_gap of a plane with an optional orifice."""
        d = x - self.geo_vector(k, POINT)
        a = self.geo_vector(k, AXIS)
        hole = self.params.geo[k, HOLE]
        z = d.dot(a)
        rho, e = self.radial(d, a)
        gap = z - r
        n = a
        if rho < hole:
            if z >= 0:
                to_rim = (rho - hole) * e + z * a
                dist = to_rim.norm()
                gap = dist - r
                n = to_rim / dist
            else:
                gap = hole - rho - r
                n = -e
        return gap, n

    @ti.func
    def cone_gap(self, k, x, r):
        """surface_gap of a cone or cylinder (meridian segment, module docstring)."""
        g = ti.static(self.params.geo)
        d = x - self.geo_vector(k, POINT)
        a = self.geo_vector(k, AXIS)
        t = d.dot(a)
        rho, e = self.radial(d, a)
        r0 = g[k, R0]
        length = g[k, LENGTH]
        seg = ti.Vector([length, g[k, R1] - r0])
        if length < 0:
            seg = ti.Vector([ti.cast(1, self.real), ti.cast(0, self.real)])
        span = seg.norm()
        along = (ti.Vector([t, rho - r0])).dot(seg) / (span * span)
        sign = ti.cast(1, self.real) if g[k, INSIDE] > 0 else ti.cast(-1, self.real)
        gap = ti.cast(0, self.real)
        n2 = ti.Vector([seg[1], -seg[0]]) / span * sign     # towards the open side
        if length < 0 or (along > 0 and along < 1):
            side = (ti.Vector([t, rho - r0])).dot(n2)
            if length >= 0 and side < 0:    # behind a finite shell: its back face
                side = -side
                n2 = -n2
            gap = side - r
        else:
            end = ti.Vector([ti.cast(0, self.real), r0])
            if along >= 1:
                end = ti.Vector([length, g[k, R1]])
            off = ti.Vector([t, rho]) - end
            dist = off.norm()
            gap = dist - r
            n2 = off / dist
        return gap, n2[0] * a + n2[1] * e

    @ti.func
    def path_gap(self, k, x, v, r, s):
        """surface_gap at the position of s [s] before the end of the step on the
        sphere's ballistic path (x, v: at the end of the step)."""
        xs = x - v * s
        if ti.static(self.f.gravity):
            xs += ti.cast(0.5, self.real) * self.params.gravity[None] * s * s
        return self.surface_gap(k, xs, r)

    @ti.func
    def contact_back(self, k, x, v, r, h):
        """Time s in (0, h] [s] since the sphere (past object k at the end of the step)
        touched it on its path, by bisection to the last bit; -1 if it was already
        past it at the step's start."""
        gap_start, n_start = self.path_gap(k, x, v, r, h)
        out = ti.cast(-1, self.real)
        if gap_start >= 0:
            lo = ti.cast(0, self.real)      # past the surface
            hi = h                          # clear of it
            for _ in range(ti.static(64 if self.real == ti.f64 else 32)):
                mid = ti.cast(0.5, self.real) * (lo + hi)
                if mid <= lo or mid >= hi:
                    break
                gap, n = self.path_gap(k, x, v, r, mid)
                if gap < 0:
                    lo = mid
                else:
                    hi = mid
            out = hi
        return out

    @ti.func
    def geometry_impacts(self, i):
        """Collide sphere i with every geometry object it went past in this step (module
        docstring)."""
        r = self.state.rad(i)
        h = self.params.h[None]
        for k in range(self.params.n_geo[None]):
            x = self.state.x[i]
            gap, n_end = self.surface_gap(k, x, r)
            if gap < 0:
                v = self.state.v[i]
                s = self.contact_back(k, x, v, r, h)
                if s >= 0:
                    self.surface_impact(i, k, s, r)
                elif ti.static(not self.f.contacts):
                    self.put_on_surface(i, k, gap, n_end)

    @ti.func
    def surface_impact(self, i, k, s, r):
        """Sphere i touched object k s [s] ago: collide there if it is an impact (faster
        than the impact speed where that applies), carry the change forward."""
        v = self.state.v[i]
        vc = v
        acc = ti.cast(0, self.real)
        gap, n = self.path_gap(k, self.state.x[i], v, r, s)
        if ti.static(self.f.gravity):
            vc = v - self.params.gravity[None] * s
            acc = self.params.gravity[None].dot(n)
        un = vc.dot(n)
        impact = un < 0
        if ti.static(self.f.contacts):
            impact = -un >= self.wall_impact_speed(i, acc)
        if impact:
            e = self.params.geo[k, RESTITUTION]
            m = self.state.mass_of(i)
            dv = -(1 + e) * un * n
            loss = ti.cast(0.5, self.real) * m * (1 - e * e) * un * un
            if ti.static(self.f.friction):
                ut = tangential_part(contact_velocity(vc, vc * 0, self.state.omega[i], vc * 0,
                                                      r, r, n), n)
                p = walton_impulse(ut, -(1 + e) * un * m, m, self.params.geo[k, FRICTION],
                                   self.params.beta_max[None])
                self.state.omega[i] += spin_change(r, self.state.inv_inertia_of(i), n, p)
                after = ut + ti.cast(3.5, self.real) / m * p
                loss += ti.cast(1 / 7, self.real) * m * (ut.norm_sqr() - after.norm_sqr())
                dv += p / m
                if ti.static(self.f.rolling):
                    self.surface_rolling(i, r, n, -(1 + e) * un * m)
            self.state.x[i] += dv * s
            self.state.v[i] = v + dv
            self.state.moved[i] += dv.norm() * s
            ti.atomic_add(self.params.energy_wall_restitution[None], loss)
            ti.atomic_add(self.params.wall_collisions[None], 1)
            self.count_hit(i)

    @ti.func
    def put_on_surface(self, i, k, gap, n):
        """Without a contact solver: a sphere past object k (gap < 0) since before the
        step (a pair collision carried it there) is put back on it and its approach is
        reflected with the object's restitution (energy never grows for e <= 1
        without gravity along n)."""
        self.state.x[i] += -gap * n
        self.state.moved[i] += -gap
        un = self.state.v[i].dot(n)
        if un < 0:
            e = self.params.geo[k, RESTITUTION]
            self.state.v[i] += -(1 + e) * un * n
            ti.atomic_add(self.params.energy_wall_restitution[None],
                          ti.cast(0.5, self.real) * self.state.mass_of(i) * (1 - e * e) * un * un)
            ti.atomic_add(self.params.wall_collisions[None], 1)
