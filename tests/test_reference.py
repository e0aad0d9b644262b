"""The exact event-driven reference (taichi_spheres.reference) against closed forms,
conservation laws, and the engine.

1. ``test_two_body_closed_form``: head-on and oblique impacts, unequal masses and
   radii, e in {0.5, 1}, with and without gravity: positions and velocities after
   the collision equal the analytic answer (free flight to the contact time from
   the plain quadratic, impulse, free flight on) to ~1e-13.
2. ``test_ball_drop_*``: bounce times t_k, apex heights e^(2k) h0 (1e-12) and wall
   collision counts; with e < 1 the ball comes to rest (rest rule) at the analytic
   time t0 (1+e)/(1-e) and stays on the floor.
3. ``test_resting_sphere_hit_from_above``: a sphere resting on the floor (rest rule,
   acceleration cancelled) hit by a falling one: the contact time (quartic path,
   relative acceleration != 0) and the velocities after it are analytic.
4. ``test_elastic_gas_conserves``: 100 spheres, periodic and walled, thousands of
   collisions: kinetic energy to ~1e-13 relative, momentum (periodic) to round-off,
   no overlaps.
5. ``test_agrees_with_engine``: dilute periodic gas, ~3 collisions per sphere: the
   engine (f64 on the test arch, step_fraction 0.01) and the reference agree.
   Measured on cpu (f64), gas(64, packing=0.05), T = 4: 105 pair collisions in
   both, max position error 2.9e-10 of the box, max velocity error 1.5e-8 m/s
   (the error grows with the number of collisions: 1.3e-13 L at T = 1, 2.3e-12 L at
   T = 2, 4.3e-11 L at T = 3 -- chaotic amplification of round-off).
6. ``test_virial_identity``: for an elastic cluster flying apart in free space (no
   walls hit, no gravity), d/dt sum_i x_i . p_i = 2 KE + impulses, so
   sum x.p (T) - sum x.p (0) = 2 KE T + virial exactly: the accumulated virial
   equals that independent sum to round-off (measured 3e-15 relative, ~50 collisions,
   unequal radii and masses).
7. ``test_virial_pressure_carnahan_starling``: periodic elastic gas, 125 spheres,
   packing 0.25, ~28 collisions per sphere: P V / N k T from the virial is within 5 %
   of Carnahan-Starling (measured +1.9 %: finite N, a lattice start, ~1700 collisions).
8. ``test_sphere_coming_to_rest_on_a_resting_sphere_raises``: a sphere dropped nearly
   on top of one resting on an e_w = 0 floor bounces on it ever more weakly until it
   would rest on it (sustained contact, not modelled): the reference raises instead
   of losing the contact (before, the micro-collisions ended by round-off and the
   upper sphere sank 0.32 sigma (e = 1) or 0.42 sigma (e = 0.9) into the lower one).
"""
import math

import numpy as np
import pytest

from conftest import walled_gravity_gas
from taichi_spheres.builders import gas
from taichi_spheres.reference import EventDrivenReference
from taichi_spheres.scene import Scene

G = 9.81


def _kinetic(st):
    return 0.5 * float(np.sum(st.mass[:, None] * st.v ** 2))


def _contact_time(d, u, sigma):
    """Plain quadratic (well conditioned for these geometries): |d + u t| = sigma."""
    a, b, c = u @ u, 2.0 * (d @ u), d @ d - sigma ** 2
    return (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)


@pytest.mark.parametrize("e", [0.5, 1.0])
@pytest.mark.parametrize("offset", [0.0, 0.37])      # head-on / oblique (impact parameter)
@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, -G)])
def test_two_body_closed_form(e, offset, gravity):
    r = np.array([0.5, 0.3])
    m = np.array([1.0, 3.7])
    x = np.array([[-2.0, offset, 0.1], [1.5, 0.0, 0.0]])
    v = np.array([[1.3, 0.0, 0.0], [-0.6, 0.05, 0.0]])
    g = np.array(gravity)
    scene = Scene.from_arrays(x, v, r, mass=m, box=((-50.0,) * 3, (50.0,) * 3),
                              gravity=gravity, restitution=e)
    ref = EventDrivenReference(scene)
    T = 2.5                       # falls ~31 m of the 50 m below: no wall

    sigma = r.sum()
    tc = _contact_time(x[0] - x[1], v[0] - v[1], sigma)
    assert 0 < tc < T
    xc = x + v * tc + 0.5 * g * tc ** 2
    vc = v + g * tc
    n = (xc[0] - xc[1]) / np.linalg.norm(xc[0] - xc[1])
    un = (vc[0] - vc[1]) @ n
    J = (1 + e) * m[0] * m[1] / m.sum() * un
    vc[0] -= J * n / m[0]
    vc[1] += J * n / m[1]
    s = T - tc
    x_end = xc + vc * s + 0.5 * g * s ** 2
    v_end = vc + g * s

    ref.advance_to(T)
    st = ref.state()
    assert ref.stats["pair_collisions"] == 1 and ref.stats["wall_collisions"] == 0
    np.testing.assert_allclose(st.x, x_end, rtol=0, atol=1e-13 * 50)
    np.testing.assert_allclose(st.v, v_end, rtol=0, atol=1e-13 * 5)
    p0, p1 = (m[:, None] * v).sum(0) + m.sum() * g * T, (m[:, None] * st.v).sum(0)
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-13 * 10)
    # virial = sigma (1+e) m_eff |u.n|
    assert ref.virial == pytest.approx(sigma * (1 + e) * m[0] * m[1] / m.sum() * abs(un),
                                       rel=1e-13)
    if e == 1.0 and not any(gravity):
        assert _kinetic(st) == pytest.approx(0.5 * float(np.sum(m[:, None] * v ** 2)),
                                             rel=1e-14)


def _drop(e, h0=1.0, r=0.1):
    scene = Scene.from_arrays([[0.5, 0.5, r + h0]], [[0.0, 0.0, 0.0]], r,
                              box=((0.0, 0.0, 0.0), (1.0, 1.0, 10.0)),
                              gravity=(0.0, 0.0, -G), wall_restitution=e)
    return scene, EventDrivenReference(scene)


@pytest.mark.parametrize("e", [1.0, 0.8])
def test_ball_drop_bounces_and_apexes(e):
    h0, r = 1.0, 0.1
    scene, ref = _drop(e, h0, r)
    t0 = math.sqrt(2 * h0 / G)
    t_bounce = t0                 # time of bounce k (k = 0, 1, ...)
    for k in range(12):
        ref.advance_to(t_bounce)
        st = ref.state()
        # at the bounce instant: on the floor (the event at t_bounce was processed,
        # or lies within round-off of it)
        assert abs(st.x[0, 2] - r) < 1e-12 * h0
        assert ref.stats["wall_collisions"] in (k, k + 1)
        apex = t_bounce + e ** (k + 1) * t0
        ref.advance_to(apex)
        st = ref.state()
        assert ref.stats["wall_collisions"] == k + 1
        assert abs(st.x[0, 2] - (r + e ** (2 * (k + 1)) * h0)) < 1e-12 * h0
        assert abs(st.v[0, 2]) < 1e-12 * G * t0
        np.testing.assert_array_equal(st.x[0, :2], [0.5, 0.5])
        t_bounce = apex + e ** (k + 1) * t0
    assert ref.stats["wall_rests"] == 0


def test_ball_drop_comes_to_rest():
    e, h0, r = 0.5, 1.0, 0.1
    scene, ref = _drop(e, h0, r)
    t0 = math.sqrt(2 * h0 / G)
    v0 = G * t0
    t_rest = t0 * (1 + e) / (1 - e)
    # rest rule: outgoing speed e^(k+1) v0 below rest_speed at bounce k
    K = next(k for k in range(200) if e ** (k + 1) * v0 < ref.rest_speed)
    assert ref.rest_speed == pytest.approx(1e-9 * math.sqrt(G * 10.0))
    # the rest begins at bounce K, t_K = t_rest - 2 t0 e^(K+1)/(1-e)
    t_K = t_rest - 2 * t0 * e ** (K + 1) / (1 - e)
    assert t_rest - t_K < 1e-8 * t0
    ref.advance_to(t_K * (1 - 1e-12))
    assert ref.stats["wall_rests"] == 0
    ref.advance_to(t_rest)
    assert ref.stats["wall_rests"] == 1
    assert ref.stats["wall_collisions"] == K + 1
    st = ref.state()
    assert st.x[0, 2] == r and st.v[0, 2] == 0.0
    ref.advance(100.0)               # stays on the floor, no more events
    st = ref.state()
    assert st.x[0, 2] == r and st.v[0, 2] == 0.0
    assert ref.stats["wall_collisions"] == K + 1


def test_max_events_raises():
    scene, _ = _drop(0.5)
    ref = EventDrivenReference(scene, rest_speed=0.0, max_events=50)
    with pytest.raises(RuntimeError, match="max_events=50"):
        ref.advance_to(10.0)


def test_resting_sphere_hit_from_above():
    """Lower sphere rests on the floor (e_w = 0); the upper one falls on it off-centre.
    The contact (lower: no acceleration, upper: g) is a quartic-path event."""
    r, m, b, z0 = 0.2, 1.0, 0.15, 1.5
    x = np.array([[1.0, 1.0, r], [1.0 + b, 1.0, z0]])
    scene = Scene.from_arrays(x, np.zeros((2, 3)), r, mass=m,
                              box=((0.0,) * 3, (2.0, 2.0, 5.0)), gravity=(0, 0, -G),
                              restitution=1.0, wall_restitution=0.0)
    ref = EventDrivenReference(scene)
    ref.advance_to(0.0)              # the resting contact at t = 0 puts it to rest
    assert ref.stats["wall_rests"] == 1
    zc = r + math.sqrt((2 * r) ** 2 - b ** 2)
    tc = math.sqrt(2 * (z0 - zc) / G)
    vz = -G * tc
    n = np.array([-b, 0.0, r - zc]) / (2 * r)          # lower minus upper, unit
    u = np.array([0.0, 0.0, -vz])                       # v_lower - v_upper
    J = (1 + 1.0) * m * m / (2 * m) * (u @ n)
    v_low = -J * n / m
    v_up = np.array([0.0, 0.0, vz]) + J * n / m
    assert v_low[2] < 0                                  # pushed into the floor:
    v_low[2] = 0.0                                       # e_w = 0 keeps it resting
    dt = 1e-3
    ref.advance_to(tc + dt)
    st = ref.state()
    assert ref.stats["pair_collisions"] == 1
    np.testing.assert_allclose(st.v[0], v_low, rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.v[1], v_up + [0, 0, -G * dt], rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.x[0], x[0] + v_low * dt, rtol=0, atol=1e-12)
    xu = np.array([1.0 + b, 1.0, zc]) + v_up * dt + [0, 0, -0.5 * G * dt * dt]
    np.testing.assert_allclose(st.x[1], xu, rtol=0, atol=1e-12)


@pytest.mark.parametrize("periodic", [True, False])
def test_elastic_gas_conserves(periodic):
    scene = gas(100, packing=0.2, periodic=periodic, gravity=(0.0, 0.0, 0.0))
    ref = EventDrivenReference(scene)
    st0 = ref.state()
    e0 = _kinetic(st0)
    p_scale = float(np.sum(scene.mass * np.linalg.norm(scene.v, axis=1)))
    ref.advance_to(12.0)
    st = ref.state()
    assert ref.stats["pair_collisions"] > 2000
    assert (ref.stats["wall_collisions"] > 500) != periodic
    assert abs(_kinetic(st) / e0 - 1) < 1e-13
    if periodic:
        p = (st.mass[:, None] * st.v).sum(0)
        assert np.abs(p).max() < 1e-14 * p_scale
    # no overlaps, everything inside the box
    d = st.x[:, None] - st.x[None]
    if periodic:
        d -= scene.box_size * np.round(d / scene.box_size)
    dist = np.linalg.norm(d, axis=2) + np.eye(scene.n) * 1e9
    sigma = st.radius[:, None] + st.radius[None]
    assert (dist >= sigma * (1 - 1e-12)).all()
    assert ((st.x >= scene.box_lo) & (st.x <= scene.box_hi)).all()
    assert ref.virial > 0


def test_agrees_with_engine(arch):
    import taichi_spheres as ts
    scene = gas(64, packing=0.05, periodic=True)
    L = float(scene.box_size[0])
    sim = ts.Simulation(scene, arch=arch, precision="f64", step_fraction=0.01) \
        if arch != "metal" else pytest.skip("needs f64")
    ref = EventDrivenReference(scene)
    T = 4.0
    sim.advance_to(T)
    ref.advance_to(T)
    a, b = sim.state(), ref.state()
    d = a.x - b.x
    d -= L * np.round(d / L)
    assert 2 * ref.stats["pair_collisions"] >= 3 * scene.n   # >= 3 collisions per sphere
    assert sim.stats["pair_collisions"] == ref.stats["pair_collisions"]
    assert np.abs(d).max() < 1e-6 * L
    assert np.abs(a.v - b.v).max() < 1e-5


def test_walled_gravity_gas_agrees_with_engine_at_default_settings(arch):
    """30 spheres of unequal masses in a walled box under gravity (e = 0.7, wall e = 0.8),
    none resting in [0, 0.5] s: the engine at its default impact speed follows the
    reference: every collision is an impact (slow impacts on side walls and the ceiling
    keep their restitution: only floor-like walls have an impact speed), and the
    contact solver finds nothing to do."""
    import taichi_spheres as ts
    if arch == "metal":
        pytest.skip("needs f64")
    scene = walled_gravity_gas()
    L = float(scene.box_size[0])
    sim = ts.Simulation(scene, arch=arch, precision="f64", step_fraction=0.01)
    assert sim.rest_speed > 0.1
    ref = EventDrivenReference(scene)
    sim.advance_to(0.5)
    ref.advance_to(0.5)
    a, b = sim.state(), ref.state()
    assert sim.stats["pair_collisions"] == ref.stats["pair_collisions"] > 100
    assert sim.stats["wall_collisions"] == ref.stats["wall_collisions"] > 100
    assert sim.stats["collapse_collisions"] == 0 and sim.stats["energy_contacts"] == 0
    assert np.abs(a.x - b.x).max() < 1e-6 * L
    assert np.abs(a.v - b.v).max() < 1e-5


def test_virial_identity():
    rng = np.random.default_rng(1)
    k = 3
    n = k ** 3
    r = 0.5 * (1.0 - 0.3 * rng.random(n))                          # m
    m = 1000.0 * 4.0 / 3.0 * math.pi * r ** 3 * (1.0 + rng.random(n))  # kg
    lattice = np.stack(np.meshgrid(*(np.arange(k),) * 3, indexing="ij"), -1).reshape(-1, 3)
    g = (lattice - (k - 1) / 2.0) * 1.1                              # m, spacing 1.1 > 2 r
    x = g + 50.0
    v = rng.normal(size=(n, 3)) - g                                  # m/s, converging
    v -= (m[:, None] * v).sum(0) / m.sum()
    scene = Scene.from_arrays(x, v, r, mass=m, box=((0.0,) * 3, (100.0,) * 3),
                              gravity=(0.0, 0.0, 0.0))
    ref = EventDrivenReference(scene)
    T = 5.0
    ref.advance_to(T)
    st = ref.state()
    assert ref.stats["wall_collisions"] == 0
    assert ref.stats["pair_collisions"] >= 40
    ke = 0.5 * float(np.sum(m[:, None] * v ** 2))
    xp = lambda xx, vv: float(np.sum(xx * (m[:, None] * vv)))
    w = xp(st.x, st.v) - xp(x, v) - 2.0 * ke * T
    assert ref.virial > 0
    assert ref.virial == pytest.approx(w, rel=1e-11)


def test_virial_pressure_carnahan_starling():
    eta = 0.25
    scene = gas(125, packing=eta, periodic=True, gravity=(0.0, 0.0, 0.0), seed=0)
    ref = EventDrivenReference(scene)
    T = 4.0
    ref.advance_to(T)
    assert ref.stats["pair_collisions"] > 10 * scene.n
    nkt = 2.0 / 3.0 * _kinetic(ref.state())                          # J
    z = (nkt + ref.virial / (3.0 * T)) / nkt                         # P V / N k T
    z_cs = (1 + eta + eta ** 2 - eta ** 3) / (1 - eta) ** 3
    assert z == pytest.approx(z_cs, rel=0.05)


@pytest.mark.parametrize("e", [1.0, 0.9])
def test_sphere_coming_to_rest_on_a_resting_sphere_raises(e):
    r, b, z0 = 0.2, 0.05, 1.0                       # m; b: horizontal offset
    x = np.array([[1.0, 1.0, r], [1.0 + b, 1.0, z0]])
    scene = Scene.from_arrays(x, np.zeros((2, 3)), r, box=((0.0,) * 3, (2.0, 2.0, 5.0)),
                              gravity=(0, 0, -G), restitution=e, wall_restitution=0.0)
    ref = EventDrivenReference(scene)
    t_hit = math.sqrt(2 * (z0 - r - math.sqrt((2 * r) ** 2 - b ** 2)) / G)
    ref.advance_to(t_hit * (1 - 1e-9))
    assert ref.stats["pair_collisions"] == 0
    with pytest.raises(RuntimeError, match="spheres 0 and 1 come to rest.*sustained contact"):
        ref.advance_to(0.6)
    # up to the collapse the pair never overlapped
    st = ref.state()
    assert np.linalg.norm(st.x[0] - st.x[1]) >= 2 * r * (1 - 1e-12)
    assert ref.stats["pair_collisions"] >= 1
