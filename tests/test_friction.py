"""Friction and rotation (contacts/friction.py, friction_rows.py), static geometry
(surfaces.py) and sinks (discharge.py) against closed forms: sliding to rolling,
inclines in both regimes, Walton's oblique impacts on a wall and between two spheres,
angular momentum, energy, and spheres held in cylinders and hoppers and discharged
through an orifice.

Tolerances: relative, scaled by the precision's machine epsilon (conftest.tol) where
the closed form is reached to round-off.
"""
import math

import numpy as np
import pytest
import taichi as ti

import taichi_spheres as ts
from taichi_spheres import observe
from taichi_spheres.builders import box_pile
from taichi_spheres.config import Tuning
from taichi_spheres.reference import walton_impact

from conftest import brute_overlap, tol

G = 9.81


def _one(x, v, r, omega=None, box=((0, 0, 0), (1, 1, 1)), **kw):
    """A scene of the given spheres (water density) with friction settings kw."""
    return ts.Scene.from_arrays(np.atleast_2d(x), np.atleast_2d(v), r, box=box,
                                omega=None if omega is None else np.atleast_2d(omega), **kw)


def oblique_pair(w1, arch, **kw):
    """(Simulation, (v, w, r, m, n)) of two spheres (radii 10 and 15 mm, water density)
    touching along an oblique normal n and approaching, with spins w1 and (20, 0, 30)
    rad/s, no gravity; kw: the restitution and friction arguments of the scene."""
    r = np.array([0.01, 0.015])
    n = np.array([-0.8, -0.36, 0.48])
    n /= np.linalg.norm(n)
    x = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]])
    x[1] -= n * r.sum()
    v = np.array([[0.6, 0.2, -0.3], [-0.4, 0.1, 0.05]])
    w = np.array([w1, (20.0, 0.0, 30.0)], dtype=float)
    m = 1000 * 4 / 3 * np.pi * r ** 3
    sc = ts.Scene.from_arrays(x, v, r, box=((0, 0, 0), (1, 1, 1)), gravity=(0, 0, 0),
                              omega=w, **kw)
    return ts.Simulation(sc, arch=arch, precision="f64"), (v, w, r, m, n)


def assert_impact(st, v, r, want_v, want_w):
    """Velocities and spins (as surface speeds) of the pair within 1e-12 of the largest
    speed before the impact."""
    scale = np.abs(v).max()
    for got, exp in zip((st.v[0], st.v[1]), want_v):
        assert np.abs(got - exp).max() < 1e-12 * scale
    for got, exp, ri in zip((st.omega[0], st.omega[1]), want_w, r):
        assert np.abs(got - exp).max() * ri < 1e-12 * scale


def closed_form_tolerance(plain, relaxation):
    """Relative tolerance of a closed form a sphere on a support reaches: ``plain``
    (round-off) with plain Gauss-Seidel sweeps; 1e-6 with over-relaxed ones (the
    default), whose normal impulse stops within the solver's tolerance
    (Rules.contact_tolerance), not at round-off."""
    return plain if relaxation == 1.0 else max(1e-6, plain)


#: (precision, Rules.relaxation): the default over-relaxation in both precisions, and
#: plain sweeps (closed forms to round-off) in f64, where the tolerances differ
CLOSED_FORM_RUNS = [("f64", 1.0), ("f64", Tuning().physics.relaxation),
                    ("f32", Tuning().physics.relaxation)]


@pytest.mark.parametrize("precision, relaxation", CLOSED_FORM_RUNS, indirect=["precision"])
def test_sliding_sphere_rolls_at_five_sevenths(arch, precision, relaxation):
    """v0 on the floor with no spin: slides with deceleration mu g until t = 2 v0 / (7 mu
    g), then rolls at 5/7 v0 with omega = v / r (angular momentum about the contact)."""
    r, mu, v0 = 0.05, 0.3, 1.0
    sc = _one([0.2, 0.5, r], [v0, 0, 0], r, box=((0, 0, 0), (2, 1, 1)), restitution=0.5,
              wall_restitution=0.5, friction=mu)
    sim = ts.Simulation(sc, arch=arch, precision=precision,
                        tuning=Tuning().with_(relaxation=relaxation))
    t_roll = 2 * v0 / (7 * mu * G)
    sim.advance_to(0.98 * t_roll)
    st = sim.state()
    assert st.v[0, 0] == pytest.approx(v0 - mu * G * st.time,
                                       rel=closed_form_tolerance(tol(precision, 64), relaxation))
    assert st.v[0, 0] > st.omega[0, 1] * r          # still slipping
    sim.advance_to(t_roll + 2 * sim.last_step["h"])
    for _ in range(2):
        st = sim.state()
        assert st.v[0, 0] == pytest.approx(5 / 7 * v0, rel=max(1e-6, tol(precision, 64)))
        assert st.omega[0, 1] * r == pytest.approx(5 / 7 * v0, rel=max(1e-6, tol(precision, 64)))
        assert np.abs(st.v[0, 1:]).max() < tol(precision, 64)
        sim.advance(0.2)


@pytest.mark.parametrize("precision, relaxation", CLOSED_FORM_RUNS, indirect=["precision"])
def test_rolling_and_twisting_resistance_act_each_in_full(arch, precision, relaxation):
    """A sphere rolling on the floor (v0, omega_y = v0 / r) while spinning about the
    vertical: the rolling resistance and the twisting resistance are each a torque of
    mu_r r m g (bounded each on its own, as LAMMPS and Project Chrono bound them), so
    it rolls with a = -5/7 mu_r g and its twist slows by 5/2 mu_r g / r, as if the
    other were absent."""
    r, mu, mu_r, v0, twist = 0.02, 0.5, 0.05, 0.5, 20.0
    sc = _one([0.2, 0.5, r], [v0, 0, 0], r, omega=[0, v0 / r, twist],
              box=((0, 0, 0), (2, 1, 1)), restitution=0.5, wall_restitution=0.5,
              friction=mu, rolling_friction=mu_r)
    sim = ts.Simulation(sc, arch=arch, precision=precision,
                        tuning=Tuning().with_(relaxation=relaxation))
    sim.advance(0.2)
    st = sim.state()
    rel = closed_form_tolerance(max(1e-9, tol(precision, 4096)), relaxation)
    assert st.v[0, 0] == pytest.approx(v0 - 5 / 7 * mu_r * G * st.time, rel=rel)
    assert st.omega[0, 2] == pytest.approx(twist - 2.5 * mu_r * G / r * st.time, rel=rel)
    assert st.omega[0, 1] * r == pytest.approx(st.v[0, 0], rel=rel)     # still rolling


@pytest.mark.parametrize("precision, relaxation", CLOSED_FORM_RUNS, indirect=["precision"])
@pytest.mark.parametrize("degrees", [20.0, 60.0])
def test_sphere_on_incline(arch, precision, degrees, relaxation):
    """A sphere released on a plane tilted by theta: rolls with a = 5/7 g sin(theta) when
    tan(theta) <= 7/2 mu, else slides with a = g (sin(theta) - mu cos(theta))."""
    r, mu = 0.02, 0.3
    th = math.radians(degrees)
    n = np.array([-math.sin(th), 0.0, math.cos(th)])
    p0 = np.array([0.5, 0.5, 0.5])
    sc = _one(p0 + r * n, [0, 0, 0], r, restitution=0.5, wall_restitution=0.5, friction=mu,
              geometry=[ts.Plane(p0, n)])
    sim = ts.Simulation(sc, arch=arch, precision=precision,
                        tuning=Tuning().with_(relaxation=relaxation))
    sim.advance(0.1)
    st = sim.state()
    down = np.array([-math.cos(th), 0.0, -math.sin(th)])
    rolls = math.tan(th) <= 3.5 * mu
    a = 5 / 7 * G * math.sin(th) if rolls else G * (math.sin(th) - mu * math.cos(th))
    plain = max(1e-9, tol(precision, 4096))
    assert st.v[0] @ down == pytest.approx(a * 0.1, rel=closed_form_tolerance(plain, relaxation))
    assert abs((st.x[0] - p0) @ n - r) < 1e-4 * 2 * r
    slip = st.v[0] @ down - st.omega[0, 1] * -r
    assert (abs(slip) < 1e-6) == rolls


@pytest.mark.parametrize("beta0, w1", [(0.44, (0, 0, 0)), (0.44, (0, 400, -100)),
                                       (-1.0, (0, 0, 0))])
def test_oblique_pair_impact_follows_walton(arch, beta0, w1):
    """Two glass spheres (e, mu, beta0 of Foerster et al. 1994, as docs/granular.md lists
    them) meeting obliquely, in the
    sticking and sliding (large spin) regimes: velocities and spins after the impact
    equal Walton's closed form, and the total angular momentum (orbital + spin) is
    conserved, to round-off."""
    e, mu = 0.97, 0.092
    sim, (v, w, r, m, n) = oblique_pair(w1, arch, restitution=e, friction=mu,
                                        tangential_restitution=beta0)
    before = sim.state()
    sim.advance(1e-3)
    st = sim.state()
    assert sim.stats["pair_collisions"] == 1
    want = walton_impact(v[0], v[1], w[0], w[1], r[0], r[1], m[0], m[1], n, e, mu, beta0)
    assert_impact(st, v, r, want[:2], want[2:])
    l0 = observe.angular_momentum(before)
    l1 = observe.angular_momentum(st)
    assert np.abs(l1 - l0).max() < 1e-12 * np.abs(l0).max()
    assert observe.total_energy(st, (0, 0, 0)) <= observe.total_energy(before, (0, 0, 0))


@pytest.mark.parametrize("w0", [(0, 0, 0), (0, -300, 0), (0, 2000, 0)])
def test_oblique_wall_impact_follows_walton(arch, w0):
    """A spinning sphere hitting the floor obliquely (no gravity): rebound velocity and
    spin equal Walton's closed form for the wall (infinite mass) in both regimes."""
    e, mu, beta0, r = 0.9, 0.2, 0.4, 0.01
    v = np.array([0.7, -0.2, -1.0])
    sc = _one([0.5, 0.5, r * 1.5], v, r, omega=w0, gravity=(0, 0, 0), wall_restitution=e,
              wall_friction=mu, tangential_restitution=beta0)
    sim = ts.Simulation(sc, arch=arch, precision="f64")
    sim.advance(0.01)
    st = sim.state()
    m = 1000 * 4 / 3 * np.pi * r ** 3
    want = walton_impact(v, np.zeros(3), np.array(w0, float), np.zeros(3), r, 0.0, m, math.inf,
                  np.array([0.0, 0.0, 1.0]), e, mu, beta0)
    assert sim.stats["wall_collisions"] == 1
    assert np.abs(st.v[0] - want[0]).max() < 1e-13
    assert np.abs(st.omega[0] - want[2]).max() * r < 1e-13


def test_friction_off_compiles_no_spin():
    """Without friction no spin field exists and st.omega is zero."""
    sc = _one([0.5, 0.5, 0.5], [1, 0, 0], 0.01, gravity=(0, 0, 0))
    sim = ts.Simulation(sc, arch="cpu", precision="f64")
    assert sim.debug_view().state.omega is None
    assert not sim.features.friction
    sim.advance(0.5)
    assert np.all(sim.state().omega == 0)


def _pile(n_side=4, mu=0.5, mu_r=0.0, e=0.5, seed=3):
    """n_side^2 x 3 spheres dropped from a jittered lattice into a small box
    (builders.box_pile)."""
    return box_pile(n_side, friction=mu, rolling_friction=mu_r, restitution=e, seed=seed)


@pytest.mark.parametrize("mu_r", [0.0, 0.1])
def test_frictional_pile_energy_is_booked_and_settles(arch, mu_r):
    """A frictional pile: total energy (spin included) stays below the start at every
    step and every joule is booked; with rolling friction it comes to rest (without it
    a sphere on the floor may roll on: no force slows a rolling sphere) and grows from
    one step to the next only by what the split impulse's removal of the last
    overlaps (~1e-8 of a diameter) lifts (booked in energy_contacts: measured 2e-11 of
    the energy at most). Overlaps stay small: below 2.5e-3 of a diameter after any
    step (1.6e-3 and 1.8e-3 measured, in the landing, where a solve's position update
    pushes a sphere into a neighbour about to hit it), and the settled pile's last
    step leaves less than 1e-5."""
    sim = ts.Simulation(_pile(mu_r=mu_r), arch=arch, precision="f64")
    energy = [sim.energy_budget()["current"]]
    for _ in range(1500):
        sim.advance(sim.max_step())
        energy.append(sim.energy_budget()["current"])
    energy = np.array(energy)
    assert energy.max() <= energy[0] * (1 + 1e-12)
    budget = sim.energy_budget()
    assert abs(budget["unaccounted"]) <= 1e-9 * abs(budget["initial"])
    assert sim.stats["max_overlap"] < 2.5e-3
    assert sim.last_step["max_overlap"] < 1e-5
    if mu_r > 0:
        assert np.diff(energy).max() <= 1e-10 * energy[0]
        st = sim.state()
        assert np.abs(st.v).max() < 1e-6
        assert np.abs(st.omega * st.radius[:, None]).max() < 1e-6


def test_box_filling_pile_settles_and_holds(arch, precision):
    """300 spheres (10 x 10 x 3) dropped into a box they fill, friction 0.5 and rolling
    friction 0.1: settled within 2 s (overlaps <= 1e-4 of a diameter, speeds and
    spin speeds at the precision's floor: 1e-6 m/s in f64), then held for 10 s without
    drift (<= 1e-4 of a diameter). In f64 the settled solve converges (residual within
    the tolerance, a few sweeps per step) and its warm start matters: restarted
    without it from the same state, the solves run >= 5x the sweeps (measured: 2
    against 100, the cap; the f32 floor keeps its solves at the cap either way)."""
    scene = _pile(n_side=10, mu=0.5, mu_r=0.1)
    floor = 1e-6 if precision == "f64" else 1e-3
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    sim.advance_to(2.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= floor
    assert np.abs(st.omega * st.radius[:, None]).max() <= floor
    settled, x = sim.checkpoint(), st.x.copy()
    sweeps, steps = sim.stats["contact_iterations"], sim.stats["steps"]
    sim.advance_to(12.0)                        # no drift over 10 s
    st = sim.state()
    assert np.abs(st.x - x).max() <= 1e-4 * 2 * st.radius.min()
    assert np.abs(st.v).max() <= floor
    assert np.abs(st.omega * st.radius[:, None]).max() <= floor
    assert brute_overlap(st, scene) <= 1e-4
    assert sim.stats["sweep_limit_hits"] == 0
    if precision != "f64":
        return
    assert sim.last_step["contact_residual"] <= \
        sim.tuning.physics.contact_tolerance * sim.rest_speed
    warm = (sim.stats["contact_iterations"] - sweeps) / (sim.stats["steps"] - steps)
    assert warm <= 5
    cold = ts.Simulation(scene, arch=arch, precision=precision,
                         tuning=Tuning().with_(warm_start=False))
    cold.restore(settled)
    sweeps, steps = cold.stats["contact_iterations"], cold.stats["steps"]
    cold.advance_to(2.5)
    assert (cold.stats["contact_iterations"] - sweeps) / (cold.stats["steps"] - steps) \
        >= 5 * warm


def test_frictional_solve_same_bits_on_both_paths_and_interleavings(arch):
    """The frictional solve gives the same bits on the serial path (every loop on one
    thread) and on the parallel one (forced with the HOST_ONLY sphere counts at 0: one
    launch per colour, its cells spread over the runtime's threads, Taichi's default
    count), and with one cell per sweep loop iteration or several interleaved
    (Performance.frictional_interleave, parallel_interleave): the parallel sweeps'
    bits do not depend on how their cells are spread over threads (CPU properties)."""
    if arch != "cpu":
        pytest.skip("the serial path and the interleavings are CPU settings")
    parallel = dict(serial_light_below=0, serial_heavy_below=0, serial_solver_below=0,
                    few_pairs=0, serial_resolve_pairs=0)
    digests, solvers = [], {}
    for interleave, path in ((8, "serial"), (1, "serial"), (1, "parallel"), (4, "parallel")):
        forced = parallel if path == "parallel" else {}
        tuning = Tuning().with_(frictional_interleave=interleave,
                                parallel_interleave=interleave, **forced)
        sim = ts.Simulation(_pile(), arch=arch, precision="f64", tuning=tuning)
        sim.advance(0.3)
        st = sim.state()
        digests.append((observe.state_digest(st, "f64"), st.omega.tobytes()))
        solvers.setdefault(path, set()).add(sim.debug_view().solver)
    assert all(d == digests[0] for d in digests[1:])
    # each path's runs share its engine (the serial one has its own: Schedule's flags),
    # with a serial solve kernel or a sweep kernel per interleaving (the engines may
    # hold earlier tests' kernels too)
    (serial,), (spread,) = solvers["serial"], solvers["parallel"]
    assert {key[0] for key in serial._serial_solves} >= {8, 1}
    assert {key[3] for key in spread._sweeps} >= {1, 4}


def _silo(hole, mu=0.5, recycle=False, n_side=5):
    """Spheres in a cylinder of radius 0.05 m standing on a plane at z = 0.05 with an
    orifice of radius ``hole``; a sink below the plane."""
    r = 0.005
    g = (np.arange(n_side) - (n_side - 1) / 2) * 0.013
    x = np.array([(0.06 + a, 0.06 + b, 0.06 + 0.012 * k) for a in g for b in g
                  for k in range(4)], float)
    x = x[np.hypot(x[:, 0] - 0.06, x[:, 1] - 0.06) < 0.045 - r]
    return ts.Scene.from_arrays(
        x, np.zeros_like(x), r, box=((0, 0, 0), (0.12, 0.12, 0.2)), restitution=0.5,
        wall_restitution=0.5, friction=mu,
        geometry=[ts.Plane((0.06, 0.06, 0.05), (0, 0, 1), hole=hole),
                  ts.Cylinder((0.06, 0.06, 0.05), (0, 0, 1), 0.05, length=0.15)],
        sinks=[ts.Sink((0, 0, 0), (0.12, 0.12, 0.03), recycle=recycle)])


def test_silo_holds_without_orifice_and_discharges_through_it(arch):
    """Without an orifice the cylinder and floor hold every sphere (inside, resting,
    small gaps); with one wider than a few diameters spheres leave through it into
    the sink, which counts them and their mass, and energy stays booked."""
    closed = ts.Simulation(_silo(hole=None), arch=arch, precision="f64")
    closed.advance(0.5)
    st = closed.state()
    rho = np.hypot(st.x[:, 0] - 0.06, st.x[:, 1] - 0.06)
    assert np.all(rho + st.radius <= 0.05 * (1 + 1e-3))
    assert np.all(st.x[:, 2] - st.radius >= 0.05 - 1e-3 * 0.01)
    assert closed.stats["discharged"] == 0
    assert np.abs(st.v).max() < 1e-2
    open_ = ts.Simulation(_silo(hole=0.02), arch=arch, precision="f64")
    n0 = open_.n
    open_.advance(0.5)
    s = open_.stats
    assert s["discharged"] > 0 and open_.n == n0 - s["discharged"]
    assert s["discharged_mass"] == pytest.approx(s["discharged"] * open_.scene.mass[0])
    budget = open_.energy_budget()
    assert abs(budget["unaccounted"]) < 1e-6 * abs(budget["initial"])


def _shell(x, r, point, r0, r1, length):
    """(gap [m], side) of sphere surfaces at x (N, 3), radii r (N,), and a finite cone
    along z from ``point`` (radius r0 there, r1 at ``length`` above): the distance to
    either face, or to a rim beyond the ends, minus r; side: +1 or -1 for the side of
    the cone's surface the centre is on where it projects onto it (axis side: +1),
    0 beyond the ends."""
    d = np.atleast_2d(x) - np.asarray(point)
    t, rho = d[:, 2], np.hypot(d[:, 0], d[:, 1])
    seg = np.array([length, r1 - r0])
    along = (t * seg[0] + (rho - r0) * seg[1]) / (seg @ seg)
    a = np.clip(along, 0.0, 1.0)
    gap = np.hypot(t - a * seg[0], rho - r0 - a * seg[1]) - r
    side = np.sign(t * seg[1] - (rho - r0) * seg[0]) * ((along > 0) & (along < 1))
    return gap, side


#: (cone (point, r0, r1, length), inside, start [m] and velocity [m/s] of the sphere,
#: the side of the shell (_shell) behind it, the direction the back face sends it): a
#: funnel's outlet with a sphere below it and outside its rim, thrown up; a flat
#: platform cone (scenes/heap.toml's) with a sphere beside it and below, thrown in
#: under it and up (spheres start in front of a face)
SHELLS = {
    "funnel's outside": (((0.15, 0.15, 0.2), 0.018, 0.05, 0.08), True,
                         (0.185, 0.15, 0.19), (0, 0, 1.2), -1, (1, 0, 0)),
    "platform's underside": (((0.15, 0.15, 0.139), 0.06, 0.0, 0.001), False,
                             (0.22, 0.15, 0.125), (-0.6, 0, 0.5), 1, (0, 0, -1)),
}


@pytest.mark.parametrize("case", SHELLS)
def test_a_sphere_behind_a_finite_cone_meets_its_back_face(arch, case):
    """A finite cone is a shell with two faces: a sphere that gets behind it (below a
    funnel's outlet and outside its rim; under a platform cone), thrown against it,
    bounces off the back face and never crosses the shell (had the back been solid,
    the gap would jump from the rim distance to minus the distance to the surface
    where the sphere starts to project onto the cone, and the sphere was pushed
    through the shell in one step)."""
    (point, r0, r1, length), inside, start, v0, behind, kick = SHELLS[case]
    r = 0.003
    scene = ts.Scene.from_arrays(
        np.array([start]), np.array([v0], dtype=float), r,
        box=((0, 0, 0), (0.3, 0.3, 0.4)), restitution=0.5, wall_restitution=0.5,
        geometry=[ts.Cone(point, (0, 0, 1), r0, r1, length, inside=inside)])
    sim = ts.Simulation(scene, arch=arch, precision="f64")
    closest, sides = np.inf, set()
    while sim.time < 0.15:
        sim.advance(sim.max_step())
        gap, side = _shell(sim.state().x, r, point, r0, r1, length)
        closest = min(closest, float(gap[0]))
        sides.add(int(side[0]))
    assert sim.stats["wall_collisions"] >= 1            # it met the back face
    assert sides - {0} == {behind}                      # and stayed behind the shell
    assert closest > -1e-4 * 2 * r
    assert float(np.dot(sim.state().v[0], kick)) > 0    # sent back by the back face


#: shells whose numpy gap with both faces must equal the kernels' (surface_gap): a
#: platform cone, a tilted hopper, finite tubes inside and outside, an infinite tube
GAP_SHELLS = [ts.Cone((0.5, 0.5, 0.3), (0, 0, 1), 0.3, 0.0, 0.1, inside=False),
              ts.Cone((0.5, 0.5, 0.3), (0, 0.6, 0.8), 0.05, 0.3, 0.3),
              ts.Cylinder((0.5, 0.5, 0.2), (0, 0, 1), 0.2, length=0.4),
              ts.Cylinder((0.5, 0.5, 0.2), (0, 0, 1), 0.2, length=0.4, inside=False),
              ts.Cylinder((0.5, 0.5, 0.2), (1, 0, 0), 0.2)]


@pytest.mark.parametrize("k", range(len(GAP_SHELLS)))
def test_the_start_check_sees_the_gap_the_kernels_see(arch, k):
    """Cone.gap(both_faces=True), the start check's gap, is the kernels' gap (two faces
    of a finite shell, a solid back of an infinite tube) at random points."""
    shape = GAP_SHELLS[k]
    start = [0.5, 0.5, 0.25] if shape.length is None else [0.05, 0.05, 0.9]
    scene = ts.Scene.from_arrays(np.array([start]), np.zeros((1, 3)), 0.01, geometry=[shape])
    motion = ts.Simulation(scene, arch=arch, precision="f64").debug_view().motion
    pts = np.random.default_rng(k).uniform(0, 1, (2000, 3))
    r = 0.02
    xs = ti.Vector.ndarray(3, ti.f64, len(pts))
    xs.from_numpy(pts)
    out = ti.ndarray(ti.f64, len(pts))

    @ti.kernel
    def kernel_gaps(xs: ti.types.ndarray(), out: ti.types.ndarray()):
        for i in range(out.shape[0]):
            out[i] = motion.surface_gap(0, xs[i], ti.cast(r, ti.f64))[0]

    kernel_gaps(xs, out)
    both = shape.gap(pts, np.full(len(pts), r), both_faces=True)
    assert np.abs(out.to_numpy() - both).max() < 1e-12


def test_recycled_spheres_reenter_at_the_top(arch):
    """With recycle the sphere count stays; discharged spheres re-enter at rest in free
    spots at the top of the box."""
    sim = ts.Simulation(_silo(hole=0.02, recycle=True), arch=arch, precision="f64")
    n0 = sim.n
    sim.advance(0.4)
    assert sim.n == n0 and sim.stats["discharged"] > 0
    st = sim.state()
    assert np.all(st.x[:, 2] >= 0.03)          # none left in the sink


def test_checkpoint_after_a_discharge_and_an_empty_simulation(arch):
    """A checkpoint taken after a sink took a sphere out restores into a Simulation of
    the original scene and continues bit for bit; once every sphere has left, time
    still runs and the energy is all booked as discharged."""
    x = np.array([[0.5, 0.5, 0.15], [0.2, 0.5, 0.6]])
    scene = ts.Scene.from_arrays(x, np.zeros_like(x), 0.02, gravity=(0, 0, -9.81),
                                 restitution=0.5, wall_restitution=0.5, friction=0.3,
                                 sinks=[ts.Sink((0, 0, 0), (1, 1, 0.1))])
    sim = ts.Simulation(scene, arch=arch, precision="f64")
    sim.advance(0.2)
    assert sim.n == 1 and sim.stats["discharged"] == 1
    assert sim.sphere_ids.tolist() == [1]
    cp = sim.checkpoint()
    other = ts.Simulation(scene, arch=arch, precision="f64")
    other.restore(cp)
    sim.advance(0.1)
    other.advance(0.1)
    assert np.array_equal(sim.state().x, other.state().x)
    sim.advance(1.0)
    assert sim.n == 0 and sim.time == pytest.approx(1.3)
    budget = sim.energy_budget()
    assert budget["current"] == 0.0
    assert abs(budget["unaccounted"]) < 1e-12 * budget["initial"]


def _rolling_step(w1, w2, inv1, inv2, n, limit):
    """Closed form of the impact's rolling resistance (contacts/friction.py): the
    impulse that stops the relative spin, its rolling part (about the tangent plane)
    and its twisting part (about the normal n) each bounded by limit."""
    p = -(w1 - w2) / (inv1 + inv2)
    twist = p @ n
    roll = p - twist * n
    size = np.linalg.norm(roll)
    if size > limit:
        roll *= limit / size
    p = roll + np.clip(twist, -limit, limit) * n
    return w1 + inv1 * p, w2 - inv2 * p


@pytest.mark.parametrize("w1", [(0, 40, -10), (0, 4000, -1000)])
def test_pair_impact_with_rolling_friction(arch, w1):
    """With rolling friction mu_r an impact is Walton's, then an angular impulse opposing
    the relative spin, its rolling and twisting parts each bounded by mu_r r_eff J_n
    (stopping it when small: first case; limited: second): spins as that closed form,
    angular momentum conserved, energy removed."""
    e, mu, mu_r, beta0 = 0.5, 0.3, 0.2, 0.35
    sim, (v, w, r, m, n) = oblique_pair(w1, arch, restitution=e, friction=mu,
                                        tangential_restitution=beta0, rolling_friction=mu_r)
    before = sim.state()
    sim.advance(1e-3)
    st = sim.state()
    assert sim.stats["pair_collisions"] == 1
    want = walton_impact(v[0], v[1], w[0], w[1], r[0], r[1], m[0], m[1], n, e, mu, beta0)
    meff = m[0] * m[1] / m.sum()
    jn = (1 + e) * meff * abs((v[0] - v[1]) @ n)
    inv = 1 / (0.4 * m * r ** 2)
    w_a, w_b = _rolling_step(want[2], want[3], inv[0], inv[1], n,
                             mu_r * r.prod() / r.sum() * jn)
    assert_impact(st, v, r, want[:2], (w_a, w_b))
    l0 = observe.angular_momentum(before)
    assert np.abs(observe.angular_momentum(st) - l0).max() < 1e-12 * np.abs(l0).max()
    assert observe.total_energy(st, (0, 0, 0)) < observe.total_energy(before, (0, 0, 0))
    budget = sim.energy_budget()
    assert abs(budget["unaccounted"]) <= 1e-12 * abs(budget["initial"])


def test_wall_impact_with_rolling_friction(arch):
    """A spinning sphere hitting the floor: Walton's impact, then its rolling spin and
    its twist (about the vertical) each reduced by at most mu_r r J_n / I (the sphere's
    material's mu_r; both bounds act here)."""
    e, mu, mu_r, beta0, r = 0.9, 0.2, 0.1, 0.4, 0.01
    v = np.array([0.7, -0.2, -1.0])
    w0 = np.array([0.0, -300.0, 50.0])
    sc = _one([0.5, 0.5, r * 1.5], v, r, omega=w0, gravity=(0, 0, 0), wall_restitution=e,
              wall_friction=mu, tangential_restitution=beta0, rolling_friction=mu_r)
    sim = ts.Simulation(sc, arch=arch, precision="f64")
    sim.advance(0.01)
    st = sim.state()
    m = 1000 * 4 / 3 * np.pi * r ** 3
    want = walton_impact(v, np.zeros(3), w0, np.zeros(3), r, 0.0, m, math.inf,
                         np.array([0.0, 0.0, 1.0]), e, mu, beta0)
    w_a, _ = _rolling_step(want[2], np.zeros(3), 1 / (0.4 * m * r * r), 0.0,
                           np.array([0.0, 0.0, 1.0]), mu_r * r * (1 + e) * m * 1.0)
    assert sim.stats["wall_collisions"] == 1
    assert np.abs(st.v[0] - want[0]).max() < 1e-13
    assert np.abs(st.omega[0] - w_a).max() * r < 1e-13
