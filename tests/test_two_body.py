"""Two-body physics against closed forms (docs/design.md, "Physics").

What is checked, and against what:

1. ``test_pair_collisions_closed_form``: pairs in free space (big box, no gravity)
   collide mid-run; final velocities, positions, momentum and kinetic-energy loss
   are compared with the exact solution (free flight to the analytic contact time,
   impulse ``J = (1+e) m_i m_j/(m_i+m_j) (u.n)``, free flight to the end), for
   head-on and oblique (b = sigma/2) impacts, mass ratios 1, 3 and 1e6, e in {0, 1/2, 1}.
2. ``test_seed_angular_*``: the seed paper's eqs. (8)-(14) (angles theta, phi of the
   line of centres, body 2 at rest) agree with the impulse form away from
   theta = 90 deg (20000 random geometries, and the engine for a few). Near 90 deg
   (theta = pi/2 - zeta) the angular form keeps the horizontal components but loses
   the vertical one (relative error ~ eps/zeta: ~1e-8 at zeta = 1e-9), kicks
   vertically when the line of centres is exactly horizontal (tan(fl(pi/2)) =
   1.6e16), and with tan theta taken as horizontal/vertical distance gives NaN
   (zeta = 0) or silently drops the impulse (zeta = 1e-200, tan^2 overflows); the
   impulse form stays within a few ulps component by component (exact rational
   reference), and the engine leaves the vertical velocity of two spheres meeting
   side by side under gravity bit-for-bit untouched.
3. ``test_single_step_rewind``: a pair that overlaps at the end of one ``step(h)``
   is put back at exactly touching distance at its contact time, with and without
   gravity.
4. ``test_ball_drop``: a ball dropped on the floor bounces at the analytic time and
   rises to the analytic apex ``e^2 (h0 - r)``.
5. ``test_periodic_pair_matches_interior_pair``: a pair colliding across a periodic
   corner behaves like the same pair in the middle of the box.

Tolerances: every error is compared with ``tol(precision, factor)`` (a multiple of
the machine epsilon of the precision under test) times the natural scale of the
quantity. The engine integrates free flight step by step (``x += v h``), so
round-off grows with the number of steps; factors of the form ``ROUNDOFF_PER_STEP *
steps`` are that linear error budget (a few roundings of the scale per step), not a
fudge. A position error delta tilts the contact normal by delta/sigma, so velocity
(and momentum, energy) errors are allowed the extra factor ``1 + X/sigma`` (X the
coordinate scale). Reference solutions are computed in float64 from the inputs *as the engine
stores them* (rounded to float32 for f32), so that input rounding is not counted as
an engine error.
"""
from fractions import Fraction

import numpy as np
import pytest

import taichi_spheres as ts
from conftest import EPS, tol

#: roundings of the scale per integration step allowed for (each step: a multiply-add
#: per coordinate, plus the time and step length themselves being rounded)
ROUNDOFF_PER_STEP = 4.0
#: roundings allowed for a handful of straight-line float operations (one collision,
#: one closed-form evaluation): a generous constant multiple of one ulp
FEW_ROUNDINGS = 16.0

G = 9.81
NO_GRAVITY = (0.0, 0.0, 0.0)
DOWN = (0.0, 0.0, -G)


# ---------------------------------------------------------------------------
# reference physics (numpy, float64)
# ---------------------------------------------------------------------------
def unit(a):
    a = np.asarray(a, dtype=np.float64)
    return a / np.linalg.norm(a)


def stored(a, precision):
    """The values as the engine holds them (float32-rounded for f32), in float64."""
    a = np.asarray(a, dtype=np.float64)
    return a.astype(np.float32).astype(np.float64) if precision == "f32" else a.copy()


def contact_time(d0, u, sigma):
    """Earliest t >= 0 with |d0 + u t| = sigma, for a separated pair approaching
    (cancellation-free smaller root)."""
    b = float(d0 @ u)
    uu = float(u @ u)
    c = float(d0 @ d0) - sigma * sigma
    disc = b * b - uu * c
    assert c > 0 and b < 0 and disc > 0, "pair must be separated and on a collision course"
    return c / (-b + np.sqrt(disc))


def impulse_form(v1, v2, m1, m2, n, e=1.0):
    """docs/design.md: u = v1 - v2, J = (1+e) m1 m2/(m1+m2) (u.n), v1 -= J n/m1, v2 += J n/m2.
    Works on (3,) or (K, 3) arrays (n unit vectors)."""
    un = np.sum((v1 - v2) * n, axis=-1, keepdims=True)
    j = (1.0 + e) * (m1 * m2 / (m1 + m2)) * un
    return v1 - j * n / m1, v2 + j * n / m2


def seed_angular(v1, v2, m1, m2, tan_t, cos_p, sin_p):
    """The seed paper's eqs. (8)-(14), elastic: theta, phi = polar and azimuthal angle
    of the line of centres; worked in the frame where body 2 rests, then shifted back.
    Works on (3,) or (K, 3) arrays."""
    w = v1 - v2
    tan_t, cos_p, sin_p = (np.asarray(a, dtype=np.float64)[..., None] for a in (tan_t, cos_p, sin_p))
    dvz2 = 2.0 * (w[..., 2:3] + tan_t * (cos_p * w[..., 0:1] + sin_p * w[..., 1:2])) \
        / ((1.0 + tan_t ** 2) * (1.0 + m2 / m1))                                  # (8)
    k = np.concatenate([tan_t * cos_p, tan_t * sin_p, np.ones_like(tan_t)], axis=-1)
    return v1 - (m2 / m1) * dvz2 * k, v2 + dvz2 * k                                # (9)-(14)


def angles_of(d):
    """theta (from +z) and phi of the line of centres d, computed the accurate way."""
    d = np.asarray(d, dtype=np.float64)
    theta = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    phi = np.arctan2(d[..., 1], d[..., 0])
    return theta, phi


def exact_impulse_fraction(v1, v2, m1, m2, d, e=1):
    """Exact rational velocity changes (dv1, dv2) for line of centres d (any length):
    (u.n) n = (u.d) d/|d|^2 needs no square root, so Fractions give the exact answer
    for the float inputs."""
    F = [Fraction(float(c)) for c in d]
    u = [Fraction(float(a)) - Fraction(float(b)) for a, b in zip(v1, v2)]
    m1, m2, e = Fraction(m1), Fraction(m2), Fraction(e)
    ud = sum(a * b for a, b in zip(u, F))
    dd = sum(a * a for a in F)
    dv1 = [-(1 + e) * m2 / (m1 + m2) * ud * c / dd for c in F]
    dv2 = [(1 + e) * m1 / (m1 + m2) * ud * c / dd for c in F]
    return np.array([float(c) for c in dv1]), np.array([float(c) for c in dv2])


def exact_pair(x1, x2, v1, v2, m1, m2, sigma, e, t_end, gravity=NO_GRAVITY):
    """Exact state of an isolated pair at t_end: ballistic flight, one collision at the
    analytic contact time (relative motion is linear even under gravity), flight on."""
    g = np.asarray(gravity, dtype=np.float64)
    tc = contact_time(x1 - x2, v1 - v2, sigma)
    assert tc <= t_end
    n = unit((x1 - x2) + (v1 - v2) * tc)
    v1c, v2c = impulse_form(v1, v2, m1, m2, n, e)      # gravity adds the same to both
    dv1, dv2 = v1c - v1, v2c - v2
    s = t_end - tc
    ballistic = lambda x, v: x + v * t_end + 0.5 * g * t_end ** 2      # noqa: E731
    return dict(tc=tc, n=n, s=s, dv1=dv1, dv2=dv2,
                x1=ballistic(x1, v1) + dv1 * s, x2=ballistic(x2, v2) + dv2 * s,
                v1=v1 + g * t_end + dv1, v2=v2 + g * t_end + dv2,
                un=float((v1 - v2) @ n))


def perpendicular(a, rng):
    """A random unit vector perpendicular to a."""
    r = rng.normal(size=3)
    r -= (r @ a) / (a @ a) * a
    return unit(r)


def pair_on_course(centre, direction, b_perp, impact, speed, v_target, t_contact, sigma, m1, m2):
    """Positions/velocities of a pair (1 = projectile, 2 = target moving at v_target)
    whose relative velocity is speed * direction, with impact parameter ``impact``
    along b_perp, touching at t_contact; centred (by mass) on ``centre``."""
    u = speed * direction
    d0 = -direction * (speed * t_contact + np.sqrt(sigma ** 2 - impact ** 2)) + impact * b_perp
    x1 = centre + m2 / (m1 + m2) * d0
    x2 = centre - m1 / (m1 + m2) * d0
    return x1, x2, v_target + u, np.asarray(v_target, dtype=np.float64)


def build(x, v, radius, mass, precision, arch, **kw):
    scene = ts.Scene.from_arrays(np.asarray(x), np.asarray(v), np.asarray(radius),
                                 mass=np.asarray(mass), **kw)
    return ts.Simulation(scene, arch=arch, precision=precision, step_fraction=0.1)


def report(what, **errors):
    """Print measured relative errors (visible with pytest -s)."""
    print(f"\n[{what}] " + ", ".join(f"{k}={v:.3g}" for k, v in errors.items()))


def rel(err, scale):
    return float(np.max(np.abs(err))) / float(scale)


# ---------------------------------------------------------------------------
# 1. two-body collisions against the closed form, collision mid-run
# ---------------------------------------------------------------------------
#: (impact parameter / sigma, m1, m2, r1, r2, target at rest)
PAIR_CASES = [
    (0.0, 1.0, 1.0, 0.5, 0.5, False),
    (0.5, 1.0, 1.0, 0.5, 0.5, False),
    (0.0, 3.0, 1.0, 0.5, 0.5, False),
    (0.5, 1.0, 3.0, 0.5, 0.3, False),
    (0.0, 1.0, 1.0e6, 0.5, 0.5, True),
    (0.5, 1.0, 1.0e6, 0.4, 0.5, True),
]
T_CONTACT = 1.0
T_END = 2.0


def _pair_scene(rng):
    xs, vs, rs, ms = [], [], [], []
    for k, (bf, m1, m2, r1, r2, at_rest) in enumerate(PAIR_CASES):
        sigma = r1 + r2
        direction = unit(rng.normal(size=3))
        centre = np.array([-10.0 + 10.0 * (k % 3), -5.0 + 10.0 * (k // 3), 2.5 * (k % 2)])
        v_target = np.zeros(3) if at_rest else rng.uniform(-0.5, 0.5, size=3)
        x1, x2, v1, v2 = pair_on_course(centre, direction, perpendicular(direction, rng),
                                        bf * sigma, 1.0, v_target, T_CONTACT, sigma, m1, m2)
        xs += [x1, x2]
        vs += [v1, v2]
        rs += [r1, r2]
        ms += [m1, m2]
    return np.array(xs), np.array(vs), np.array(rs), np.array(ms)


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_pair_collisions_closed_form(arch, precision, e):
    x, v, r, m = _pair_scene(np.random.default_rng(1))
    sim = build(x, v, r, m, precision, arch, box=((-20.0,) * 3, (20.0,) * 3),
                gravity=NO_GRAVITY, restitution=e)
    xs, vs = stored(x, precision), stored(v, precision)
    sim.advance(T_END)
    st = sim.state()
    steps = sim.stats["steps"]
    X = np.abs(xs).max() + np.abs(vs).max() * T_END          # coordinate scale [m]
    budget = tol(precision, ROUNDOFF_PER_STEP * steps)
    if e > 0:
        assert sim.stats["pair_collisions"] == len(PAIR_CASES)
    else:
        # e = 0 head-on: the pair travels on touching; a round-off re-contact may add
        # a (round-off sized) impulse, which the velocity checks below bound
        assert sim.stats["pair_collisions"] >= len(PAIR_CASES)
    assert sim.stats["unresolved"] == 0
    assert sim.stats["max_overlap"] <= budget
    worst = dict(v=0.0, x=0.0, p=0.0, ke=0.0)
    for k, (bf, m1, m2, r1, r2, _) in enumerate(PAIR_CASES):
        i, j = 2 * k, 2 * k + 1
        sigma = r1 + r2
        ref = exact_pair(xs[i], xs[j], vs[i], vs[j], m1, m2, sigma, e, T_END)
        assert 0.4 * T_END < ref["tc"] < 0.6 * T_END            # collision mid-run
        speed = np.linalg.norm(vs[i]) + np.linalg.norm(vs[j])
        # a position error delta tilts the normal by delta/sigma: velocity errors scale
        # with the speed times X/sigma, on top of the velocity round-off itself
        tilt = 1.0 + X / sigma
        err_v = max(rel(st.v[i] - ref["v1"], speed), rel(st.v[j] - ref["v2"], speed))
        err_x = max(rel(st.x[i] - ref["x1"], X), rel(st.x[j] - ref["x2"], X))
        assert err_v <= budget * tilt, f"pair {k}: velocity error {err_v:.3g} > {budget * tilt:.3g}"
        assert err_x <= budget, f"pair {k}: position error {err_x:.3g} > {budget:.3g}"

        # momentum conserved, to round-off of the momenta involved
        p0 = m1 * vs[i] + m2 * vs[j]
        p1 = m1 * st.v[i] + m2 * st.v[j]
        p_scale = m1 * np.linalg.norm(vs[i]) + m2 * np.linalg.norm(vs[j])
        err_p = rel(p1 - p0, p_scale)
        assert err_p <= budget * tilt, f"pair {k}: momentum error {err_p:.3g}"

        # kinetic energy lost = (1 - e^2)/2 m_eff u_n^2 exactly
        ke0 = 0.5 * (m1 * vs[i] @ vs[i] + m2 * vs[j] @ vs[j])
        ke1 = 0.5 * (m1 * st.v[i] @ st.v[i] + m2 * st.v[j] @ st.v[j])
        m_eff = m1 * m2 / (m1 + m2)
        loss = 0.5 * (1.0 - e * e) * m_eff * ref["un"] ** 2
        err_ke = abs((ke0 - ke1) - loss) / ke0
        assert err_ke <= budget * tilt, f"pair {k}: kinetic energy loss error {err_ke:.3g}"
        if e < 1.0:
            assert loss > 0.05 * ke0            # the check is not vacuous
        worst = {key: max(worst[key], val) for key, val in
                 dict(v=err_v, x=err_x, p=err_p, ke=err_ke).items()}
    report(f"closed form {precision} e={e} steps={steps}", **worst)


# ---------------------------------------------------------------------------
# 2. the seed paper's angular form (8)-(14) versus the impulse form
# ---------------------------------------------------------------------------
def test_seed_angular_form_agrees_away_from_horizontal():
    """Random non-grazing geometries (line of centres within 80 deg of the z axis,
    either way up): eqs. (8)-(14) give the impulse form's velocities to round-off."""
    rng = np.random.default_rng(7)
    k = 20000
    theta = np.where(rng.random(k) < 0.5, 1.0, -1.0) * rng.uniform(0.0, np.radians(80.0), k)
    theta = np.where(theta < 0, np.pi + theta, theta)       # [0, 80] U [100, 180] deg
    phi = rng.uniform(-np.pi, np.pi, k)
    n = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    v1 = rng.normal(size=(k, 3))
    v2 = rng.normal(size=(k, 3))
    m1 = np.exp(rng.uniform(-3.0, 3.0, (k, 1)))
    m2 = np.exp(rng.uniform(-3.0, 3.0, (k, 1)))
    a1, a2 = seed_angular(v1, v2, m1, m2, np.tan(theta), np.cos(phi), np.sin(phi))
    b1, b2 = impulse_form(v1, v2, m1, m2, n)
    # both are a few operations on O(|v|) numbers; tan theta enters squared, so its
    # rounding is amplified by at most (1 + tan^2 theta) <= 1/cos^2(80 deg) ~ 33
    amp = 1.0 + np.tan(theta) ** 2
    speed = np.linalg.norm(v1, axis=1) + np.linalg.norm(v2, axis=1)
    err = np.maximum(np.abs(a1 - b1).max(axis=1), np.abs(a2 - b2).max(axis=1)) / speed
    assert np.isfinite(a1).all() and np.isfinite(a2).all()
    assert np.all(err <= tol("f64", FEW_ROUNDINGS) * amp), (err / amp).max()
    # and the collision did something: not a vacuous agreement
    assert np.median(np.abs(b1 - v1).max(axis=1)) > 0.1
    report("angular vs impulse form, theta within 80 deg of z, f64", v=err.max(),
           v_over_amplification=(err / amp).max())


def test_seed_angular_form_loses_precision_near_horizontal():
    """Line of centres (nearly) perpendicular to z, as for two spheres side by side on
    the floor, theta = pi/2 - zeta: the impulse form gets every component of the
    result to a few ulps. The angular form with the angles theta, phi (computed as
    accurately as possible, atan2) keeps the horizontal components but loses the
    vertical one (relative error ~ eps/zeta) and kicks vertically when the exact
    answer is 0; with tan(theta) taken as horizontal/vertical distance it is accurate
    until tan^2 overflows, then drops the impulse silently (zeta = 1e-200) or gives
    NaN (zeta = 0). Reference: exact rational arithmetic on the same float inputs.
    Worked in the paper's frame, body 2 (the target) at rest, so that v2' *is* the
    velocity change and its components can be judged one by one."""
    v1 = np.array([0.75, -0.25, 0.125])
    v2 = np.zeros(3)
    m1, m2 = 1.0, 3.0
    horizontals = [np.array([0.6, 0.8]), np.array([0.3, -0.7]), np.array([1.0, 0.1])]
    eps = EPS["f64"]

    def component_errors(got, exact):
        out = np.abs(got - exact)
        nz = exact != 0
        out[nz] /= np.abs(exact[nz])
        out[~nz] = np.where(got[~nz] == 0, 0.0, np.inf)
        return out

    with np.errstate(all="ignore"):
        for zeta in (1e-3, 1e-6, 1e-9, 1e-12, 1e-200, 0.0):
            worst_ang_z = 0.0
            for hz in horizontals:
                d = np.array([hz[0], hz[1], zeta])
                ex1, ex2 = exact_impulse_fraction(v1, v2, m1, m2, d)
                assert np.linalg.norm(ex2) > 0.1               # a real collision
                # impulse form, from the geometry d: every component to a few ulps,
                # the vertical one exactly 0 when the line of centres is horizontal
                i1, i2 = impulse_form(v1, v2, m1, m2, unit(d))
                assert component_errors(i2, ex2).max() <= tol("f64", FEW_ROUNDINGS), (zeta, i2, ex2)
                assert np.abs(i1 - (v1 + ex1)).max() <= tol("f64", FEW_ROUNDINGS) * np.abs(v1).max()

                # angular form, angles computed the accurate way (atan2) from d
                theta, phi = angles_of(d)
                a1, a2 = seed_angular(v1, v2, m1, m2, np.tan(theta), np.cos(phi), np.sin(phi))
                err = component_errors(a2, ex2)
                # the horizontal components (and the norm) are still fine ...
                assert err[:2].max() <= tol("f64", FEW_ROUNDINGS)
                worst_ang_z = max(worst_ang_z, err[2])

                # the angular form with tan(theta) taken from the geometry as horizontal
                # over vertical distance: accurate (no angle in between) until it overflows
                tan_ratio = np.hypot(d[0], d[1]) / d[2]
                r1, r2 = seed_angular(v1, v2, m1, m2, tan_ratio, hz[0] / np.hypot(*hz),
                                      hz[1] / np.hypot(*hz))
                if zeta == 0.0:
                    # tan = inf: inf/inf in eq. (8)
                    assert np.isinf(tan_ratio) and np.isnan(r1).all() and np.isnan(r2).all()
                elif zeta == 1e-200:
                    # tan^2 = inf: eq. (8) gives 0 and the collision silently vanishes
                    assert np.isinf(tan_ratio ** 2)
                    assert np.array_equal(r1, v1) and np.array_equal(r2, v2)
                else:
                    assert component_errors(r2, ex2).max() <= tol("f64", FEW_ROUNDINGS)
            # ... but the vertical component is only as good as theta, whose absolute
            # rounding (~eps) is a relative error ~eps/zeta in cos(theta) = n_z
            if zeta == 0.0:
                # theta = fl(pi/2), tan = 1.6e16: a vertical kick where there is none
                assert theta == np.pi / 2 and np.tan(theta) > 1e16
                assert np.isinf(worst_ang_z)
            else:
                assert worst_ang_z >= 0.05 * eps / zeta, (zeta, worst_ang_z)
                if zeta <= 1e-6:      # far beyond anything round-off explains
                    assert worst_ang_z > tol("f64", 1e3 * FEW_ROUNDINGS)


#: contact geometries (theta, phi) for the engine check; the last two are the
#: near-horizontal and exactly horizontal lines of centres
ENGINE_GEOMETRIES = [(0.0, 0.0), (np.radians(30), np.radians(45)), (np.radians(60), np.radians(200)),
                     (np.radians(120), np.radians(-70)), (np.radians(85), np.radians(10)),
                     (np.pi / 2 - 1e-9, np.radians(53.13)), ("horizontal", np.radians(53.13))]


def test_seed_angular_form_vs_engine(arch, precision):
    """A few geometries through a Simulation (under gravity): the engine agrees with
    the angular form where it is well conditioned and with the impulse form
    everywhere; for two spheres meeting side by side (line of centres exactly
    horizontal) it adds no vertical velocity at all, bit for bit."""
    rng = np.random.default_rng(3)
    r, m1, m2 = 0.5, 1.0, 2.0
    sigma = 2 * r
    t_contact, t_end = 0.5, 1.0
    xs, vs, ms = [], [], []
    for k, (theta, phi) in enumerate(ENGINE_GEOMETRIES):
        if theta == "horizontal":
            n = np.array([np.cos(phi), np.sin(phi), 0.0])
            tangent = np.array([-np.sin(phi), np.cos(phi), 0.0])
        else:
            n = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
            tangent = perpendicular(n, rng)
        u = -0.8 * n + 0.6 * tangent                          # approaching, 37 deg off
        centre = np.array([-12.0 + 6.0 * (k % 5), -6.0 + 12.0 * (k // 5), 5.0])
        x1 = centre + 0.5 * (sigma * n - u * t_contact)
        x2 = centre - 0.5 * (sigma * n - u * t_contact)
        if theta == "horizontal":
            x1[2] = x2[2] = centre[2]                         # exactly side by side
            v2 = np.array([0.25, -0.125, 0.0])
        else:
            v2 = rng.uniform(-0.5, 0.5, 3)
        xs += [x1, x2]
        vs += [v2 + u, v2]
        ms += [m1, m2]
    xs.append([15.0, 15.0, 5.0])                              # a lone sphere, v_z = 0
    vs.append([0.0, 0.0, 0.0])
    ms.append(1.0)
    x, v, mass = np.array(xs), np.array(vs), np.array(ms)
    sim = build(x, v, r, mass, precision, arch, box=((-20.0, -20.0, -20.0), (20.0, 20.0, 20.0)),
                gravity=DOWN, restitution=1.0)
    xs, vs = stored(x, precision), stored(v, precision)
    sim.advance(t_end)
    st = sim.state()
    steps = sim.stats["steps"]
    assert sim.stats["pair_collisions"] == len(ENGINE_GEOMETRIES)
    X = np.abs(xs).max() + (np.abs(vs).max() + G * t_end) * t_end
    budget = tol(precision, ROUNDOFF_PER_STEP * steps)
    tilt = 1.0 + X / sigma             # normal tilt from position round-off, as in test 1
    worst = dict(v_impulse=0.0, v_angular=0.0, x=0.0)
    g = np.asarray(DOWN)
    for k, (theta, phi) in enumerate(ENGINE_GEOMETRIES):
        i, j = 2 * k, 2 * k + 1
        ref = exact_pair(xs[i], xs[j], vs[i], vs[j], m1, m2, sigma, 1.0, t_end, DOWN)
        speed = np.linalg.norm(vs[i]) + np.linalg.norm(vs[j]) + G * t_end
        err = max(rel(st.v[i] - ref["v1"], speed), rel(st.v[j] - ref["v2"], speed))
        assert err <= budget * tilt, f"geometry {k}: engine vs impulse form {err:.3g}"
        err_x = max(rel(st.x[i] - ref["x1"], X), rel(st.x[j] - ref["x2"], X))
        assert err_x <= budget, f"geometry {k}: position error {err_x:.3g}"
        worst["v_impulse"] = max(worst["v_impulse"], err)
        worst["x"] = max(worst["x"], err_x)
        th, ph = angles_of(ref["n"])
        if abs(np.cos(th)) > np.cos(np.radians(81)):
            # the paper's form, from the contact angles, matches the engine too
            a1, a2 = seed_angular(vs[i], vs[j], m1, m2, np.tan(th), np.cos(ph), np.sin(ph))
            amp = 1.0 + np.tan(th) ** 2
            err_a = max(rel(st.v[i] - (a1 + g * t_end), speed),
                        rel(st.v[j] - (a2 + g * t_end), speed))
            assert err_a <= budget * tilt * amp, f"geometry {k}: engine vs angular form {err_a:.3g}"
            worst["v_angular"] = max(worst["v_angular"], err_a)
    # exactly horizontal line of centres: same vertical velocity as a sphere that
    # never collided, bit for bit, and still exactly side by side
    i, j = 2 * (len(ENGINE_GEOMETRIES) - 1), 2 * len(ENGINE_GEOMETRIES) - 1
    lone = 2 * len(ENGINE_GEOMETRIES)
    assert st.v[i, 2] == st.v[lone, 2] and st.v[j, 2] == st.v[lone, 2]
    assert st.x[i, 2] == st.x[j, 2]
    assert np.linalg.norm(st.v[i, :2] - vs[i, :2]) > 0.1      # it did collide
    report(f"engine vs impulse/angular {precision} steps={steps}", **worst)


# ---------------------------------------------------------------------------
# 3. rewind to contact inside one step
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("gravity", [NO_GRAVITY, DOWN], ids=["free", "gravity"])
def test_single_step_rewind(arch, precision, gravity):
    """Pairs that overlap at the end of one step(h) end at exactly the contact-then-
    carry-forward positions: (x_i - x_j) - (v_i' - v_j') s has length r_i + r_j,
    s being the analytic time since contact."""
    rng = np.random.default_rng(11)
    h, t_contact = 0.1, 0.06               # contact 60 % into the step
    e = 0.5
    cases = [(0.0, 1.0, 1.0, 0.5, 0.5), (0.5, 1.0, 3.0, 0.5, 0.3), (0.8, 2.0, 1.0, 0.4, 0.5)]
    xs, vs, rs, ms = [], [], [], []
    for k, (bf, m1, m2, r1, r2) in enumerate(cases):
        sigma = r1 + r2
        direction = unit([0.6, -0.3, -0.8 + 0.7 * k])  # oblique, with a z component
        x1, x2, v1, v2 = pair_on_course(np.array([-5.0 + 5.0 * k, 0.5 * k, 1.0]), direction,
                                        perpendicular(direction, rng), bf * sigma, 3.0,
                                        rng.uniform(-1, 1, 3), t_contact, sigma, m1, m2)
        xs += [x1, x2]
        vs += [v1, v2]
        rs += [r1, r2]
        ms += [m1, m2]
    x, v, r, m = map(np.array, (xs, vs, rs, ms))
    sim = build(x, v, r, m, precision, arch, box=((-10.0,) * 3, (10.0,) * 3),
                gravity=gravity, restitution=e)
    xs, vs = stored(x, precision), stored(v, precision)
    sim.step(h)
    st = sim.state()
    assert sim.stats["pair_collisions"] == len(cases)
    X = np.abs(xs).max() + np.abs(vs).max() * h + G * h * h
    budget = tol(precision, FEW_ROUNDINGS)
    worst = dict(touch=0.0, x=0.0, v=0.0)
    for k, (bf, m1, m2, r1, r2) in enumerate(cases):
        i, j = 2 * k, 2 * k + 1
        sigma = r1 + r2
        ref = exact_pair(xs[i], xs[j], vs[i], vs[j], m1, m2, sigma, e, h, gravity)
        assert abs(ref["tc"] - t_contact) < 1e-3 * h
        # overlapped at the end of the step had nothing been done
        d_free = (xs[i] - xs[j]) + (vs[i] - vs[j]) * h
        assert np.linalg.norm(d_free) < (1.0 - 1e-3) * sigma
        # the engine's state, carried back by s along the post-collision velocities
        s = ref["s"]
        back = (st.x[i] - st.x[j]) - (st.v[i] - st.v[j]) * s
        err_touch = abs(np.linalg.norm(back) - sigma) / X
        err_x = max(rel(st.x[i] - ref["x1"], X), rel(st.x[j] - ref["x2"], X))
        speed = np.linalg.norm(vs[i]) + np.linalg.norm(vs[j]) + G * h
        tilt = 1.0 + X / sigma
        err_v = max(rel(st.v[i] - ref["v1"], speed), rel(st.v[j] - ref["v2"], speed))
        assert err_touch <= budget, f"pair {k}: |d - u' s| - sigma = {err_touch:.3g} (rel)"
        assert err_x <= budget, f"pair {k}: position error {err_x:.3g}"
        assert err_v <= budget * tilt, f"pair {k}: velocity error {err_v:.3g}"
        for key, val in dict(touch=err_touch, x=err_x, v=err_v).items():
            worst[key] = max(worst[key], val)
    report(f"single-step rewind {precision} g={gravity[2]}", **worst)


# ---------------------------------------------------------------------------
# 4. a ball dropped on the floor
# ---------------------------------------------------------------------------
def bouncing_ball(z0, r, e, n_bounces=4):
    """Exact height and vertical velocity of a ball dropped from rest at height z0
    onto a floor at z = 0 (contact at z = r), restitution e: returns (z(t), v(t),
    bounce times)."""
    t0 = np.sqrt(2.0 * (z0 - r) / G)
    vi = G * t0
    arcs = [(0.0, z0, 0.0)]                     # (start time, height, upward velocity)
    t = t0
    for k in range(1, n_bounces + 1):
        w = e ** k * vi
        arcs.append((t, r, w))
        t += 2.0 * w / G
    bounces = [a[0] for a in arcs[1:]]

    def state(t):
        start, z, w = [a for a in arcs if a[0] <= t][-1]
        tau = t - start
        return z + w * tau - 0.5 * G * tau * tau, w - G * tau
    return state, bounces


@pytest.mark.parametrize("e", [1.0, 0.5])
def test_ball_drop(arch, precision, e):
    """Ball A is dropped from h0 and observed exactly at its bounce times (the step
    ends at contact) and apexes: bounce at t0 = sqrt(2 (h0 - r)/g), apex
    e^2 (h0 - r) above the contact height, then the second bounce and apex. Ball B,
    dropped from another height, bounces in the middle of steps, so its state
    checks the wall rewind along the ballistic path. Horizontal motion untouched."""
    r, h0 = 0.05, 0.8
    x0 = np.array([[0.5, 0.5, h0], [0.25, 0.75, 0.6]])
    v0 = np.array([[0.0625, -0.03125, 0.0], [0.03125, 0.0625, 0.0]])
    sim = build(x0, v0, r, 1.0, precision, arch, box=((0.0,) * 3, (1.0,) * 3),
                gravity=DOWN, wall_restitution=e)
    x0s, v0s = stored(x0, precision), stored(v0, precision)
    motion = [bouncing_ball(x0s[b, 2], r, e) for b in range(2)]
    fall = x0s[0, 2] - r
    t0 = np.sqrt(2.0 * fall / G)
    vi = [G * np.sqrt(2.0 * (x0s[b, 2] - r) / G) for b in range(2)]   # impact speeds
    # ball A: (time, what, textbook height or None, exactly at a bounce)
    checks = [(0.5 * t0, "falling", None, False), (t0, "at the bounce", r, True),
              (t0 + 0.5 * e * t0, "rising", None, False), (t0 + e * t0, "apex", r + e ** 2 * fall, False),
              (t0 + 2 * e * t0, "second bounce", r, True), (t0 + 2.5 * e * t0, "rising again", None, False),
              (t0 + (2 + e) * e * t0, "second apex", r + e ** 4 * fall, False)]
    assert np.isclose(motion[0][1][1], t0 + 2 * e * t0)
    worst = dict(z=0.0, vz=0.0)
    for t, what, height, at_bounce in checks:
        sim.advance_to(t)
        st = sim.state()
        assert st.time == t
        steps = sim.stats["steps"]
        budget = tol(precision, ROUNDOFF_PER_STEP * steps)
        for b in range(2):
            z, w = motion[b][0](t)
            if b == 0 and height is not None:      # the reference is the textbook answer
                assert abs(z - height) <= tol("f64", FEW_ROUNDINGS) * h0
            err_z = abs(st.x[b, 2] - z) / h0
            assert err_z <= budget, f"ball {b} {what} (t={t:.6g}): z={st.x[b, 2]!r}, exact {z!r}"
            if b == 0 and at_bounce:
                # exactly at contact: the bounce may belong to this step or the next
                # one, so v_z is the incoming -w/e or the outgoing w
                err_vz = min(abs(st.v[b, 2] + w / e), abs(st.v[b, 2] - w)) / vi[b]
            else:
                err_vz = abs(st.v[b, 2] - w) / vi[b]
            assert err_vz <= budget, f"ball {b} {what}: v_z={st.v[b, 2]!r}, exact {w!r}"
            err_xy = np.abs(st.x[b, :2] - (x0s[b, :2] + v0s[b, :2] * t)).max() / h0
            assert err_xy <= budget and np.array_equal(st.v[b, :2], v0s[b, :2])
            worst = dict(z=max(worst["z"], err_z), vz=max(worst["vz"], err_vz))
        if not at_bounce:
            bounces = sum(tb < t for m in motion for tb in m[1])
            assert sim.stats["wall_collisions"] == bounces, (what, sim.stats)
    # B bounced mid-step at least twice; the balls never met
    assert sum(tb < checks[-1][0] for tb in motion[1][1]) >= 2
    assert sim.stats["wall_rests"] == 0 and sim.stats["pair_collisions"] == 0
    report(f"ball drop {precision} e={e} steps={sim.stats['steps']}", **worst)


# ---------------------------------------------------------------------------
# 5. a pair colliding across a periodic corner
# ---------------------------------------------------------------------------
def test_periodic_pair_matches_interior_pair(arch, precision):
    """The same pair, once straddling the x and y periodic boundaries (and
    colliding there), once in the middle of the box: same velocities, same relative
    geometry, both equal to the closed form."""
    L = 8.0
    r, e = 0.5, 0.5
    sigma = 2 * r
    rng = np.random.default_rng(5)
    direction = unit([1.0, 0.7, 0.2])
    middle = np.array([4.0, 4.0, 4.0])
    corner = np.array([0.0, 0.0, 4.0])       # contact point on the x = y = 0 edge
    t_contact, t_end = 1.0, 2.0
    x1, x2, v1, v2 = pair_on_course(middle, direction, perpendicular(direction, rng), 0.5 * sigma,
                                    1.0, np.array([0.25, -0.375, 0.125]), t_contact, sigma, 1.0, 1.0)
    # shift so that the contact point (midpoint at contact) lands on the corner
    mid_at_contact = 0.5 * (x1 + x2) + 0.5 * (v1 + v2) * t_contact
    shift = corner - mid_at_contact
    x = np.array([x1 + shift, x2 + shift, x1, x2]) % L
    v = np.array([v1, v2, v1, v2])
    sim = build(x, v, r, 1.0, precision, arch, box=((0.0,) * 3, (L,) * 3),
                periodic=(True, True, True), gravity=NO_GRAVITY, restitution=e)
    xs, vs = stored(x, precision), stored(v, precision)
    sim.advance(t_end)
    st = sim.state()
    steps = sim.stats["steps"]
    assert sim.stats["pair_collisions"] == 2
    assert np.all((st.x >= 0.0) & (st.x < L))
    budget = tol(precision, ROUNDOFF_PER_STEP * steps)
    X = L
    speed = np.linalg.norm(v1) + np.linalg.norm(v2)
    v_budget = budget * speed * (1.0 + X / sigma)     # normal tilt, as in test 1

    def wrap(a):
        return a - L * np.round(a / L)

    # the boundary pair really straddles the boundary at contact
    a_contact = xs[0] + vs[0] * t_contact, xs[1] + vs[1] * t_contact
    assert np.any(np.abs(wrap(a_contact[0] - a_contact[1]) - (a_contact[0] - a_contact[1])) > 1.0)
    # boundary pair (0, 1) against interior pair (2, 3): same velocities, and the
    # same displacements modulo the box
    err_v = np.abs(st.v[:2] - st.v[2:]).max()
    err_x = rel(wrap((st.x[:2] - xs[:2]) - (st.x[2:] - xs[2:])), X)
    assert err_v <= v_budget, f"boundary vs interior velocities differ by {err_v:.3g}"
    assert err_x <= budget, f"boundary vs interior positions {err_x:.3g}"
    # and both are the closed form (the boundary one with the image of sphere 1)
    ref = exact_pair(xs[2], xs[3], vs[2], vs[3], 1.0, 1.0, sigma, e, t_end)
    image = xs[0] + wrap(xs[1] - xs[0])
    ref_b = exact_pair(xs[0], image, vs[0], vs[1], 1.0, 1.0, sigma, e, t_end)
    for a, (rf, which) in enumerate([(ref_b, "1"), (ref_b, "2"), (ref, "1"), (ref, "2")]):
        assert np.abs(st.v[a] - rf["v" + which]).max() <= v_budget, (a, st.v[a], rf["v" + which])
        assert rel(wrap(st.x[a] - rf["x" + which]), X) <= budget, (a, st.x[a], rf["x" + which])
    report(f"periodic {precision} steps={steps}", boundary_vs_interior_v=err_v / speed,
           boundary_vs_interior_x=err_x)
