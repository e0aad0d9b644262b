"""Exact event-driven reference simulator (numpy, float64, small N): the yardstick.

Same physics and same :class:`~taichi_spheres.scene.Scene` input as the engine
(docs/design.md, "Physics"), but integrated event by event instead of in steps:

* Free flight: ``x(t+h) = x + v h + g h^2/2``, ``v += g h``.
* Pair events: gravity is the same for all spheres, so the relative motion of a
  pair is linear; the next contact of i, j is the smallest ``t >= 0`` with
  ``|d + u t| = r_i + r_j`` and ``d.u < 0`` (``d = x_i - x_j``, minimum image on
  periodic axes, ``u = v_i - v_j``), from the cancellation-free root
  ``t = c / (-b + sqrt(b^2 - |u|^2 c))``, ``b = d.u``, ``c = |d|^2 - sigma^2``.
  Collision: ``n = d/|d|`` at contact, ``J = (1+e) m_i m_j/(m_i+m_j) (u.n)``,
  ``v_i -= J n/m_i``, ``v_j += J n/m_j``.  When one sphere of the pair rests on a
  wall (see below) the accelerations differ and the contact time is the first
  root of the quartic ``|d + u t + a t^2/2|^2 = sigma^2`` (companion-matrix
  eigenvalues, polished by Newton in float64).
* Wall events (non-periodic axes): contact when ``x_a = lo_a + r`` or
  ``hi_a - r`` on the ballistic parabola, the root taken in its cancellation-free
  form; the sphere is put exactly on the contact plane and ``v_a -> -e_w v_a``.
* Periodic axes: positions are wrapped into ``[lo, hi)``; pairs use the minimum
  image.  A minimum-image prediction is only trusted for as long as no other image
  can come into contact: every other image is at least ``L/2`` away (``L`` the
  shortest periodic side), so a pair whose predicted contact lies beyond the time
  in which its relative displacement could reach ``L/2 - sigma`` gets a *re-check*
  event at that time instead (no physics, just a new prediction; counted in
  ``stats['rechecks']``).  Needs ``L > 2 sigma`` (the engine asks for 3 diameters).

Rest rule (inelastic collapse on walls; Zeno bouncing): at a wall contact where
gravity pushes the sphere into that wall, if the outgoing normal speed
``e_w |v_a|`` is below ``rest_speed`` the sphere is put *at rest on the wall*:
``v_a = 0``, and its acceleration along ``a`` is cancelled (the wall carries its
weight) until a pair impulse lifts it off (``v_a`` pointing away from the wall).
A pair impulse that pushes a resting sphere into its wall is followed at once by
a wall collision (reflect with ``e_w``, or stay resting if the outgoing speed is
below ``rest_speed``).  Default ``rest_speed = 1e-9 sqrt(|g| L_box)`` (``L_box``
the largest box side); with no gravity the rule never applies.  Energy removed by
the rule is at most ``m rest_speed^2 / 2`` per rest.  Counted in
``stats['wall_rests']``.  Inelastic collapse among *pairs* (e.g. spheres stacked
under gravity with e < 1) has no such rule: it shows up as an unbounded number of
events and raises ``RuntimeError`` once ``max_events`` is exceeded.  A sphere
that comes to rest on a sphere resting on a wall (normal speed after a pair
collision below ``rest_speed`` while the wall carries the lower sphere's weight)
would need sustained, non-impulsive contact, which the reference does not model:
it raises ``RuntimeError`` naming the pair, and the state stays that of the last
event (without the check the micro-collisions ended at round-off level and the
spheres silently sank into each other, by up to 0.9 sigma).

Bookkeeping: every sphere keeps its own state ``(x, v)`` at its own last-update
time ``t_i`` and is only advanced (exactly, from ``t_i``) when it takes part in an
event, so spheres do not accumulate per-event round-off.  Event times are absolute
float64.  Predicted times live in an ``N x N`` pair table plus a per-sphere wall
time; after an event only the rows of the spheres involved are recomputed (O(N)
each, vectorised) and the next event is the argmin of the table (O(N^2) numpy, fine
for a few hundred spheres).  Every table entry is exact for the current velocities
of both spheres, so no event is ever stale.
"""
from __future__ import annotations

import math

import numpy as np

from .scene import Scene
from .state import State

__all__ = ["EventDrivenReference", "walton_impact"]

_INF = math.inf


class EventDrivenReference:
    """Exact event-driven hard-sphere dynamics of a :class:`Scene`.

    rest_speed: normal speed below which a sphere hitting a wall that gravity pushes
    it into comes to rest on it [m/s]; None means ``1e-9 sqrt(|g| max(box side))``.
    max_events: cap on processed events (collisions + re-checks); exceeding it raises
    RuntimeError (inelastic collapse or a runaway).

    Attributes:
        stats: dict with pair_collisions, wall_collisions, wall_rests, rechecks,
            events (= pair_collisions + wall_collisions), time.
        virial: sum over pair collisions of ``r_ij . dp_i`` = ``sigma_ij (1+e)
            m_i m_j/(m_i+m_j) |u.n|`` [kg m^2/s] (``r_ij = x_i - x_j`` at contact,
            ``dp_i`` the momentum i receives).  The collisional pressure over an
            interval T in volume V is ``virial / (3 V T)`` (add ``N k T / V``).
    """

    def __init__(self, scene: Scene, rest_speed=None, max_events: int = 10_000_000):
        self.scene = scene
        n = scene.n
        self.n = n
        self._lo = np.asarray(scene.box_lo, dtype=np.float64).copy()
        self._hi = np.asarray(scene.box_hi, dtype=np.float64).copy()
        self._L = self._hi - self._lo
        self._per = np.array(scene.periodic, dtype=bool)
        self._g = np.asarray(scene.gravity, dtype=np.float64).copy()
        self._r = np.asarray(scene.radius, dtype=np.float64).copy()
        self._m = np.asarray(scene.mass, dtype=np.float64).copy()
        # pair restitution per pair of materials (materials.py)
        self._e_pair = scene.pair_values()[..., 0]
        self._material = np.asarray(scene.material)
        self._ew = float(scene.wall_restitution)
        gnorm = float(np.linalg.norm(self._g))
        if rest_speed is None:
            rest_speed = 1e-9 * math.sqrt(gnorm * float(self._L.max()))
        self.rest_speed = float(rest_speed)
        if not self.rest_speed >= 0.0:
            raise ValueError(f"rest_speed must be >= 0, got {rest_speed}")
        self.max_events = int(max_events)
        if self._per.any():
            lmin = float(self._L[self._per].min())
            if lmin <= 2.0 * 2.0 * float(self._r.max()):
                raise ValueError(f"periodic side {lmin} must exceed two largest diameters")
            self._half_l = 0.5 * lmin
        else:
            self._half_l = _INF

        self._x = np.array(scene.x, dtype=np.float64)
        self._v = np.array(scene.v, dtype=np.float64)
        self._t = np.zeros(n)                       # per-sphere last-update time
        self._rest = np.zeros((n, 3), dtype=np.int8)  # -1 on lo wall, +1 on hi wall
        self._acc = np.tile(self._g, (n, 1))
        self._now = 0.0
        self._wrap(np.arange(n))

        self._pair_t = np.full((n, n), _INF)
        self._pair_real = np.zeros((n, n), dtype=bool)   # False: re-check event
        self._wall_t = np.full(n, _INF)
        self._wall_axis = np.zeros(n, dtype=np.int64)
        self._wall_side = np.zeros(n, dtype=np.int64)

        self.virial = 0.0
        self._counts = dict(pair_collisions=0, wall_collisions=0, wall_rests=0, rechecks=0)
        for i in range(n):
            self._predict_wall(i)
        for i in range(n):
            self._predict_row(i, 0.0, others=np.arange(i + 1, n))

    # ---- public API ----
    @property
    def time(self) -> float:
        return self._now

    @property
    def stats(self) -> dict:
        out = dict(self._counts)
        out["events"] = out["pair_collisions"] + out["wall_collisions"]
        out["time"] = self._now
        return out

    def state(self) -> State:
        """Numpy copies of positions (wrapped on periodic axes), velocities, radii,
        masses at the current time."""
        idx = np.arange(self.n)
        x, v = self._at(idx, self._now)
        return State(x=self._wrapped(x), v=v, radius=self._r.copy(), mass=self._m.copy(),
                     time=self._now)

    def advance(self, duration: float) -> None:
        self.advance_to(self._now + float(duration))

    def advance_to(self, t: float) -> None:
        """Process every event with time <= t in time order, then free flight to t."""
        t = float(t)
        if not math.isfinite(t) or t < self._now:
            raise ValueError(f"cannot advance to t={t} from t={self._now}")
        n = self.n
        while True:
            k = int(np.argmin(self._pair_t))
            tp = self._pair_t.flat[k]
            w = int(np.argmin(self._wall_t))
            tw = self._wall_t[w]
            te = min(tp, tw)
            if te > t:
                break
            done = self._counts["pair_collisions"] + self._counts["wall_collisions"] \
                + self._counts["rechecks"]
            if done >= self.max_events:
                raise RuntimeError(
                    f"EventDrivenReference: more than max_events={self.max_events} events "
                    f"before t={t} (reached t={te}): inelastic collapse or runaway; "
                    f"stats={self.stats}")
            te = max(te, self._now)
            self._now = te
            if tw <= tp:
                self._wall_event(w, te)
            else:
                i, j = divmod(k, n)
                if self._pair_real[i, j]:
                    self._pair_event(i, j, te)
                else:
                    self._counts["rechecks"] += 1
                    self._predict_row(i, te, others=np.array([j]))
        self._now = t

    # ---- motion ----
    def _at(self, idx, t):
        """Positions and velocities of spheres idx at time t (not stored)."""
        dt = (t - self._t[idx])[:, None]
        a = self._acc[idx]
        return self._x[idx] + self._v[idx] * dt + 0.5 * a * dt * dt, self._v[idx] + a * dt

    def _sync(self, i, t):
        x, v = self._at(np.array([i]), t)
        self._x[i], self._v[i] = x[0], v[0]
        self._t[i] = t
        self._wrap(np.array([i]))

    def _wrapped(self, x):
        x = x.copy()
        for a in np.flatnonzero(self._per):
            y = self._lo[a] + np.mod(x[:, a] - self._lo[a], self._L[a])
            y[y >= self._hi[a]] = self._lo[a]
            x[:, a] = y
        return x

    def _wrap(self, idx):
        self._x[idx] = self._wrapped(self._x[idx])

    def _set_rest(self, i, a, side):
        self._rest[i, a] = side
        self._acc[i, a] = 0.0 if side else self._g[a]

    # ---- predictions ----
    def _predict_wall(self, i):
        best, axis, side = _INF, 0, 0
        x, v, a, r = self._x[i], self._v[i], self._acc[i], self._r[i]
        for ax in range(3):
            if self._per[ax] or self._rest[i, ax]:
                continue
            s = _wall_hit(x[ax] - (self._lo[ax] + r), v[ax], a[ax])
            if s < best:
                best, axis, side = s, ax, -1
            s = _wall_hit((self._hi[ax] - r) - x[ax], -v[ax], -a[ax])
            if s < best:
                best, axis, side = s, ax, 1
        self._wall_t[i] = self._t[i] + best
        self._wall_axis[i] = axis
        self._wall_side[i] = side

    def _predict_row(self, i, t, others=None, exclude=-1):
        """Recompute the pair events of sphere i against ``others`` (default: all)
        at time t; ``exclude`` is the partner i just collided with."""
        if others is None:
            others = np.delete(np.arange(self.n), i)
        if others.size == 0:
            return
        xi, vi = self._at(np.array([i]), t)
        xj, vj = self._at(others, t)
        d = xi - xj
        for a in np.flatnonzero(self._per):
            d[:, a] -= self._L[a] * np.round(d[:, a] / self._L[a])
        u = vi - vj
        acc = self._acc[i] - self._acc[others]
        sig = self._r[i] + self._r[others]
        tc = np.full(others.size, _INF)
        lin = ~np.any(acc != 0.0, axis=1)
        if lin.any():
            dl, ul, sl = d[lin], u[lin], sig[lin]
            b = np.einsum("ij,ij->i", dl, ul)
            c = np.einsum("ij,ij->i", dl, dl) - sl * sl
            uu = np.einsum("ij,ij->i", ul, ul)
            disc = b * b - uu * c
            ok = (b < 0.0) & (disc >= 0.0)
            with np.errstate(invalid="ignore", divide="ignore"):
                s = np.where(ok, c / (np.sqrt(np.maximum(disc, 0.0)) - b), _INF)
            s = np.maximum(s, 0.0)
            if exclude >= 0:
                s[others[lin] == exclude] = _INF   # linear relative motion: no second contact
            tc[lin] = s
        quart = np.flatnonzero(~lin)
        for q in quart:   # rare: one sphere of the pair rests on a wall
            tc[q] = _first_contact_quartic(d[q], u[q], acc[q], sig[q],
                                           just_collided=(others[q] == exclude))
        # minimum-image horizon
        real = np.ones(others.size, dtype=bool)
        if math.isfinite(self._half_l):
            D = self._half_l - sig
            un = np.linalg.norm(u, axis=1)
            an = np.linalg.norm(acc, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                H = 2.0 * D / (un + np.sqrt(un * un + 2.0 * an * D))
            H = np.where(np.isnan(H), _INF, H)
            late = tc > H
            tc = np.where(late, H, tc)
            real = ~late
        self._pair_t[i, others] = t + tc
        self._pair_t[others, i] = t + tc
        self._pair_real[i, others] = real
        self._pair_real[others, i] = real

    # ---- events ----
    def _pair_event(self, i, j, t):
        self._sync(i, t)
        self._sync(j, t)
        d = self._x[i] - self._x[j]
        for a in np.flatnonzero(self._per):
            d[a] -= self._L[a] * round(d[a] / self._L[a])
        n_hat = d / math.sqrt(float(d @ d))
        u = self._v[i] - self._v[j]
        un = float(u @ n_hat)
        mi, mj = self._m[i], self._m[j]
        if un < 0.0:
            e = float(self._e_pair[self._material[i], self._material[j]])
            J = (1.0 + e) * mi * mj / (mi + mj) * un
            self._v[i] -= J * n_hat / mi
            self._v[j] += J * n_hat / mj
            self.virial += -J * float(d @ n_hat)
        self._counts["pair_collisions"] += 1
        # a wall impulse on a resting sphere can make the pair approach again: then it
        # is not excluded and collides again at once (sequential resolution)
        walled = [self._after_impulse(k, t) for k in (i, j)]
        self._check_sustained(i, j, n_hat, t)
        for k in (i, j):
            self._predict_wall(k)
        self._predict_row(i, t, exclude=-1 if any(walled) else j)
        others = np.delete(np.arange(self.n), [i, j])
        self._predict_row(j, t, others=others)

    def _check_sustained(self, i, j, n_hat, t):
        """Raise RuntimeError if the pair i, j is left in sustained contact: normal
        speed below ``rest_speed`` [m/s] while their relative acceleration (one of them
        rests on a wall) pushes them together.  The next contact would then follow
        within ``2 rest_speed / |a_n|`` at a separation below round-off, an endless
        sequence the quartic cannot resolve: left alone, the pair lost contact and
        the spheres sank into each other under gravity."""
        un = float((self._v[i] - self._v[j]) @ n_hat)
        an = float((self._acc[i] - self._acc[j]) @ n_hat)
        if an < 0.0 and abs(un) < self.rest_speed:
            raise RuntimeError(
                f"EventDrivenReference: spheres {i} and {j} come to rest on each other at "
                f"t={t} (normal speed {un:.3g} m/s below rest_speed {self.rest_speed:.3g}, "
                f"relative acceleration {an:.3g} m/s^2 into the contact): sustained contact "
                "between spheres is not modelled")

    def _after_impulse(self, k, t):
        """A pair impulse on a resting sphere: lift off, or hit its wall at once.
        Returns whether a wall impulse was applied."""
        walled = False
        for a in range(3):
            side = int(self._rest[k, a])
            if not side:
                continue
            vin = side * self._v[k, a]       # > 0: into the wall
            if vin > 0.0:
                walled = True
                self._counts["wall_collisions"] += 1
                out = self._ew * vin
                if out < self.rest_speed:
                    self._v[k, a] = 0.0
                    self._counts["wall_rests"] += 1
                else:
                    self._v[k, a] = -side * out
                    self._set_rest(k, a, 0)
            elif vin < 0.0:
                self._set_rest(k, a, 0)
        return walled

    def _wall_event(self, i, t):
        self._sync(i, t)
        a, side = int(self._wall_axis[i]), int(self._wall_side[i])
        self._x[i, a] = self._lo[a] + self._r[i] if side < 0 else self._hi[a] - self._r[i]
        vin = side * self._v[i, a]            # speed into the wall (>= 0)
        out = self._ew * max(vin, 0.0)
        self._counts["wall_collisions"] += 1
        if side * self._g[a] > 0.0 and out < self.rest_speed:
            self._v[i, a] = 0.0
            self._set_rest(i, a, side)
            self._counts["wall_rests"] += 1
        else:
            self._v[i, a] = -side * out
        self._predict_wall(i)
        self._predict_row(i, t)


def _wall_hit(p, w, g):
    """Smallest s >= 0 with p + w s + g s^2/2 = 0 and w + g s < 0 (moving into the
    wall), p the distance to the contact plane; inf if none."""
    if p <= 0.0 and (w < 0.0 or (w == 0.0 and g < 0.0)):
        return 0.0
    if g == 0.0:
        return p / -w if w < 0.0 else _INF
    disc = w * w - 2.0 * g * p
    if disc < 0.0:
        return _INF
    sq = math.sqrt(disc)
    if w <= 0.0:
        den = sq - w
        return max(2.0 * p / den, 0.0) if den > 0.0 else _INF
    if g < 0.0:
        return (-w - sq) / g
    return _INF


def _first_contact_quartic(d, u, a, sigma, just_collided=False):
    """First time t >= 0 at which |d + u t + a t^2/2| = sigma while approaching (inf if
    none).  f(t) = |d + u t + a t^2/2|^2 - sigma^2 is a quartic; the real parts of the
    roots of f' (a cubic; extra breakpoints are harmless) cut [0, t_far] into
    monotone pieces, and the first piece on which f goes from > 0 to <= 0 holds the
    contact, found by bisection to the last bit.  Beyond t_far = (|u| + sqrt(|u|^2 +
    2|a|(|d|+sigma)))/|a| the pair is certainly apart for good."""
    A = 0.5 * a
    c4 = A @ A
    c3 = 2.0 * (u @ A)
    c2 = u @ u + 2.0 * (d @ A)
    c1 = 2.0 * (d @ u)
    s2 = sigma * sigma

    def f(t):
        p = d + u * t + A * t * t
        return p @ p - s2

    un, an, dn = math.sqrt(u @ u), math.sqrt(a @ a), math.sqrt(d @ d)
    t_far = (un + math.sqrt(un * un + 2.0 * an * (dn + sigma))) / an
    scale = sigma / (un + math.sqrt(an * sigma))
    t_start = 1e-9 * scale if just_collided else 0.0
    f0 = f(0.0)
    if not just_collided and f0 <= 0.0 and c1 < 0.0:
        return 0.0
    # touching within round-off (f0 <= 0) but separating: the distance at t = 0
    # counts as contact, the next contact is where it comes back to it
    shift = min(f0, 0.0)

    def fs(t):
        return f(t) - shift

    crit = np.roots([4.0 * c4, 3.0 * c3, 2.0 * c2, c1]).real
    pts = [t_start] + sorted(float(c) for c in crit if t_start < c < t_far) + [t_far]
    for k, (lo, hi) in enumerate(zip(pts[:-1], pts[1:])):
        flo, fhi = fs(lo), fs(hi)
        if (flo > 0.0 or (k == 0 and flo >= 0.0)) and fhi <= 0.0:
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                if not lo < mid < hi:
                    break
                if fs(mid) > 0.0:
                    lo = mid
                else:
                    hi = mid
            return hi if abs(fs(hi)) <= abs(fs(lo)) else lo
    return _INF


def walton_impact(v1, v2, w1, w2, r1, r2, m1, m2, n, e, mu, beta0):
    """Walton's impact model in closed form (Foerster et al. 1994; contacts/friction.py):
    velocities v [m/s] and spins w [rad/s] of solid spheres 1 and 2 (radii r [m],
    masses m [kg]; m2 = inf for a wall, with v2 = w2 = 0) touching along the unit
    normal n (from 2 to 1), restitution e, friction mu, tangential restitution beta0
    (-1: the sticking bound 0). Returns (v1', v2', w1', w2')."""
    v1, v2, w1, w2, n = (np.asarray(a, dtype=np.float64) for a in (v1, v2, w1, w2, n))
    inv2 = 0.0 if np.isinf(m2) else 1.0 / m2
    meff = 1.0 / (1.0 / m1 + inv2)
    uc = v1 - v2 - np.cross(r1 * w1 + r2 * w2, n)
    un = uc @ n
    ut = uc - un * n
    jn = -(1 + e) * meff * un
    speed = np.linalg.norm(ut)
    jt = min((1 + (0.0 if beta0 == -1 else beta0)) * 2 / 7 * meff * speed, mu * jn)
    p = jn * n - (jt / speed * ut if speed > 0 else 0.0)
    w1n = w1 - r1 / (0.4 * m1 * r1 ** 2) * np.cross(n, p)
    w2n = w2 if not inv2 else w2 - r2 / (0.4 * m2 * r2 ** 2) * np.cross(n, p)
    return v1 + p / m1, v2 - p * inv2, w1n, w2n
