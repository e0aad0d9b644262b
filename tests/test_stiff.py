"""Stiff and extreme cases (issue 4): resting contact (bouncing ball, column, poured
pile), restitution models, grazing/head-on/touching/coincident/zero-velocity pairs,
mass ratio 1e6, radius ratio 10, very fast spheres, Newton's cradle, inelastic
collapse."""
import os

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.config import DEFAULT
from taichi_spheres.builders import gas
from taichi_spheres.scenefile import scene_from_dict
from conftest import assert_same_counters, tol, tol_for


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_bouncing_ball_comes_to_rest_at_the_analytic_time(arch, precision, e):
    """Apex heights e^(2n) h0 and rest at t0 (1+e)/(1-e), t0 = sqrt(2 h0/g); after that
    the ball stays on the floor, and its energy never grows."""
    r, h0, g = 0.05, 0.5, 9.81
    scene = ts.Scene.from_arrays([[0.5, 0.5, r + h0]], [[0, 0, 0]], r, gravity=(0, 0, -g),
                                 wall_restitution=e)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    t0 = np.sqrt(2 * h0 / g)
    t_rest = t0 * (1 + e) / (1 - e)
    energy = [ts.observe.total_energy(sim.state(), scene.gravity)]
    # apexes: bounce k at t0 (1 + 2 e + ... + 2 e^(k-1)), apex e^k t0 later
    t_bounce = t0
    for k in range(1, 4):
        sim.advance_to(t_bounce + e ** k * t0)
        st = sim.state()
        assert st.x[0, 2] - r == pytest.approx(e ** (2 * k) * h0, rel=tol(precision, 1e3))
        energy.append(ts.observe.total_energy(st, scene.gravity))
        t_bounce += 2 * e ** k * t0
    sim.advance_to(0.999 * t_rest)
    before = sim.state()
    assert before.x[0, 2] - r > 0 or abs(before.v[0, 2]) > 0, "still bouncing just before"
    sim.advance_to(1.001 * t_rest)
    st = sim.state()
    assert st.x[0, 2] - r == pytest.approx(0.0, abs=tol(precision, 10) * h0)
    assert abs(st.v[0, 2]) < tol(precision, 10) * np.sqrt(g * h0)
    energy.append(ts.observe.total_energy(st, scene.gravity))
    sim.advance_to(3 * t_rest)
    st = sim.state()
    assert st.x[0, 2] - r == pytest.approx(0.0, abs=tol(precision, 10) * h0)
    assert abs(st.v[0, 2]) < tol(precision, 10) * np.sqrt(g * h0)
    energy.append(ts.observe.total_energy(st, scene.gravity))
    assert np.all(np.diff(energy) <= tol(precision, 10) * abs(energy[0]))
    assert sim.stats["wall_rests"] >= 1


def _check_rest(sim, scene, energies, sigma_frac, floor_frac):
    """Shared checks for resting contact: brute-force overlaps below sigma_frac of the
    contact distance, floor penetration below floor_frac of the radius, everyone in
    the box, energy never above its start (beyond round-off)."""
    st = sim.state()
    r = st.radius
    d = np.linalg.norm(st.x[:, None] - st.x[None], axis=-1) + np.eye(scene.n) * 1e9
    overlap = 1 - d / (r[:, None] + r[None])
    assert overlap.max() < sigma_frac, f"a sphere sank {overlap.max():.2e} sigma into another"
    assert np.all(st.x[:, 2] - r > -floor_frac * r), "a sphere sank into the floor"
    # walls: within the contact solver's overlap tolerance (1e-4 of a diameter)
    assert np.all(st.x - r[:, None] >= scene.box_lo - 2e-4 * r[:, None])
    assert np.all(st.x + r[:, None] <= scene.box_hi + 2e-4 * r[:, None])
    e0 = energies[0]
    assert max(energies) <= e0 + 1e-9 * abs(e0)
    return st


def test_stacked_column_comes_to_rest(arch, precision):
    """Ten spheres stacked (gaps of 1 % of r), e = 0.5: they settle on each other, no
    sphere sinks into another or into the floor by more than 1 % of r, kinetic energy
    decays to ~0, total energy never rises, no step hits the sweep limit."""
    r, n, g = 0.05, 10, 9.81
    x = np.array([[0.5, 0.5, r + (2 * r + 0.001) * k] for k in range(n)])
    scene = ts.Scene.from_arrays(x, np.zeros((n, 3)), r, gravity=(0, 0, -g),
                                 restitution=0.5, wall_restitution=0.5,
                                 box=((0, 0, 0), (1, 1, 2)))
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    assert sim.features.contacts
    energies = [ts.observe.total_energy(sim.state(), scene.gravity)]
    for t in (0.25, 0.5, 0.75, 1.0):
        sim.advance_to(t)
        energies.append(ts.observe.total_energy(sim.state(), scene.gravity))
    st = _check_rest(sim, scene, energies, 0.005, 0.01)
    # at rest: speeds at the scale of the contact solver's tolerance
    v_tol = 1e-5 if precision == "f64" else 1e-3
    assert ts.observe.kinetic_energy(st) < 0.5 * scene.mass.sum() * v_tol ** 2
    assert sim.stats["sweep_limit_hits"] == 0
    assert np.all(np.abs(st.x[:, :2] - 0.5) < 1e-9), "the column stays straight"


def _pour(count, seed=3, e=0.5):
    return scene_from_dict({
        "box": {"lo": [0.0, 0.0, 0.0], "hi": [0.2, 0.2, 0.6], "wall_restitution": e},
        "physics": {"gravity": [0.0, 0.0, -9.81], "restitution": e},
        "pour": [{"count": count, "lo": [0.02, 0.02, 0.2], "hi": [0.18, 0.18, 0.6],
                  "radius": 0.012, "density": 2500.0, "v": [0.0, 0.0, -1.0],
                  "v_spread": 0.05, "seed": seed}]}, source="pour-test")


def _settle(sim, scene, t_end, samples=6):
    energies = [ts.observe.total_energy(sim.state(), scene.gravity)]
    kinetic = [ts.observe.kinetic_energy(sim.state())]
    for t in np.linspace(t_end / samples, t_end, samples):
        sim.advance_to(t)
        st = sim.state()
        energies.append(ts.observe.total_energy(st, scene.gravity))
        kinetic.append(ts.observe.kinetic_energy(st))
    return energies, kinetic


def test_poured_pile_comes_to_rest(arch):
    """A few hundred spheres poured onto the floor (e = 0.5) settle into a pile:
    overlaps stay below 2 % of the contact distance, nothing sinks into the floor by
    more than 1 % of r, kinetic energy decays to below 1e-3 of its peak, total energy
    never rises above its start."""
    scene = _pour(300)
    sim = ts.Simulation(scene, arch=arch)
    energies, kinetic = _settle(sim, scene, 1.2)
    _check_rest(sim, scene, energies, 0.02, 0.01)
    assert kinetic[-1] < 1e-3 * max(kinetic)


def test_fused_step_matches_kernel_by_kernel_on_a_forming_pile(arch):
    """A forming pile (impacts, the contact solver, wall placements) gives the same bits
    and the same counters launched kernel by kernel and as the fused step (fused.py,
    one or two kernels per step; CPU only)."""
    stats = _fused_matches_kernel_by_kernel(arch, _pour(120), lambda sim: 0.6)
    assert stats["contacts"] > 0 and stats["pair_collisions"] > 0


def test_projection_near_sets_match_full_scans(arch):
    """Overlaps left at the sweep limit where no contact solver runs (a dense inelastic
    gas without gravity, two sweeps per step) are projected apart, and give the same
    bits and counters in three builds: the step launched kernel by kernel; the same
    with the projection scanning every sphere in every iteration instead of only those
    near the spheres it moved before (Performance.projection_near_sets); and, on the
    CPU, the fused step (projection included). On a GPU the energy books and the
    virial are sums of float atomics in thread order: equal to round-off there."""
    scene = gas(300, packing=0.45, restitution=0.5, wall_restitution=0.5)
    runs = {}
    for name in ("kernels", "full scans", "fused"):
        if name == "fused" and arch != "cpu":
            continue        # the fused step is for the CPU
        tuning = DEFAULT.with_(projection_near_sets=name != "full scans")
        sim = ts.Simulation(scene, arch=arch, fused=name == "fused", tuning=tuning,
                            max_sweeps=2)
        assert sim.fused == (name == "fused")
        assert sim.debug_view().projection.near_sets == (name != "full scans")
        sim.advance(20 * sim.max_step())
        runs[name] = (sim.state(), sim.stats)
    a, stats = runs["kernels"]
    assert stats["projected_steps"] > 0 and stats["projected_pairs"] > 0
    for b, stats_b in runs.values():
        assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
        assert_same_counters(stats, stats_b, sim)


def _fused_matches_kernel_by_kernel(arch, scene, duration, **options):
    """Run ``scene`` for ``duration(sim)`` seconds with and without the fused step;
    assert the same bits and counters; return the counters."""
    if arch != "cpu":
        pytest.skip("the fused step is for the CPU")
    runs = []
    for fused in (True, False):
        sim = ts.Simulation(scene, arch=arch, fused=fused, **options)
        assert sim.fused == fused
        sim.advance(duration(sim))
        runs.append((sim.state(), sim.stats))
    (a, stats_a), (b, stats_b) = runs
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    assert stats_a == stats_b
    return stats_a


@pytest.mark.slow
def test_large_poured_pile_comes_to_rest(arch):
    """The shipped 2000-sphere pour scene, run for 3 s."""
    scene = ts.load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes", "pour.toml"))
    sim = ts.Simulation(scene, arch=arch)
    energies, kinetic = _settle(sim, scene, 3.0)
    _check_rest(sim, scene, energies, 0.02, 0.01)
    assert kinetic[-1] < 1e-3 * max(kinetic)


# ---- restitution models: energy loss per collision against the closed form ----

def _pair(u, b, e, model, masses=(1.0, 3.0)):
    """Two spheres (r = 0.1) a small distance apart, sphere 0 moving with velocity u
    towards sphere 1 at impact parameter b (fraction of the contact distance)."""
    r = 0.1
    x = np.array([[0.3, 0.5, 0.5], [0.5, 0.5 + b * 2 * r, 0.5]])
    v = np.array([u, [0.0, 0.0, 0.0]], dtype=float)
    return ts.Scene.from_arrays(x, v, r, mass=list(masses), gravity=(0, 0, 0),
                                restitution=e, restitution_model=model)


@pytest.mark.parametrize("model", ["normal", "smid"])
@pytest.mark.parametrize("e", [0.0, 0.5, 0.9])
def test_restitution_model_energy_loss_matches_closed_form(arch, precision, model, e):
    """normal: dE = (1 - e^2)/2 m_eff u_n^2 (tangential kept); smid: the seed's rule
    (Smid 2007), dE = (1 - e^2)/2 m_eff |u|^2. The loss booked by the engine equals the
    measured one; momentum is conserved."""
    scene = _pair([1.0, 0.0, 0.0], 0.6, e, model)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    st0 = sim.state()
    sim.advance(0.5)
    st = sim.state()
    # e = 0 leaves the pair touching with u_n = 0: a round-off re-contact may follow
    # (with a vanishing impulse)
    assert sim.stats["pair_collisions"] == 1 or (e == 0 and sim.stats["pair_collisions"] <= 3)
    m = scene.mass
    meff = m[0] * m[1] / (m[0] + m[1])
    # normal at contact: sin(angle) = impact parameter
    b = 0.6
    un2 = 1.0 - b * b
    expected = 0.5 * meff * (1 - e * e) * (un2 if model == "normal" else 1.0)
    lost = ts.observe.kinetic_energy(st0) - ts.observe.kinetic_energy(st)
    assert lost == pytest.approx(expected, rel=tol(precision, 1e3), abs=tol(precision, 1e2))
    assert sim.energy_budget()["pair_restitution"] == pytest.approx(expected, rel=tol(precision, 1e3),
                                                                     abs=tol(precision, 1e2))
    p0, p1 = ts.observe.momentum(st0), ts.observe.momentum(st)
    assert np.allclose(p0, p1, atol=tol(precision, 1e2))
    if model == "normal":
        # tangential relative velocity unchanged
        n = np.array([-np.sqrt(un2), -b, 0.0])      # (x0 - x1) / sigma at contact
        t0 = (st0.v[0] - st0.v[1]) - np.dot(st0.v[0] - st0.v[1], n) * n
        t1 = (st.v[0] - st.v[1]) - np.dot(st.v[0] - st.v[1], n) * n
        assert np.allclose(t0, t1, atol=tol(precision, 1e3))


def test_smid_rule_loses_more_than_normal_on_grazing_contacts(arch):
    """The seed's rule damps the tangential relative velocity too: at impact
    parameter 0.95 it loses |u|^2/u_n^2 = 1/(1 - 0.95^2) ~ 10x the energy."""
    losses = {}
    for model in ("normal", "smid"):
        sim = ts.Simulation(_pair([1.0, 0.0, 0.0], 0.95, 0.5, model), arch=arch)
        sim.advance(0.5)
        losses[model] = sim.energy_budget()["pair_restitution"]
    assert losses["smid"] / losses["normal"] == pytest.approx(1 / (1 - 0.95 ** 2),
                                                              rel=tol_for(sim, 1e-9, 1e2))


# ---- extreme geometries: never a NaN, books balance ----

def _finite(st):
    return np.all(np.isfinite(st.x)) and np.all(np.isfinite(st.v))


@pytest.mark.parametrize("offset", [1 - 1e-12, 1 + 1e-12])
def test_grazing_collision_is_finite_and_conservative(arch, offset):
    """Impact parameter within 1e-12 of the contact distance: either a collision with
    a vanishing exchange of momentum or a miss; never a NaN; books balance."""
    scene = _pair([1.0, 0.0, 0.0], 0.5 * offset * 2, 1.0, "normal")
    sim = ts.Simulation(scene, arch=arch)
    st0 = sim.state()
    sim.advance(0.5)
    st = sim.state()
    assert _finite(st)
    # the arch's default precision (in f32 the offset rounds away: a touching graze)
    rel = tol(sim.precision, 45)     # 1e-14 in f64
    assert ts.observe.total_energy(st, scene.gravity) == pytest.approx(
        ts.observe.total_energy(st0, scene.gravity), rel=rel)
    assert np.allclose(ts.observe.momentum(st), ts.observe.momentum(st0), atol=rel)
    # the transverse kick is at most of order sqrt(offset) (in f32, the coordinates'
    # rounding sets the offset)
    assert abs(st.v[0, 1]) < (1e-5 if sim.precision == "f64" else 10 * np.sqrt(tol("f32")))


def test_head_on_equal_masses_exchange_velocities(arch, precision):
    scene = _pair([1.0, 0.0, 0.0], 0.0, 1.0, "normal", masses=(2.0, 2.0))
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    sim.advance(0.1)
    st = sim.state()
    assert np.allclose(st.v[0], 0.0, atol=tol(precision, 10))
    assert np.allclose(st.v[1], [1.0, 0.0, 0.0], atol=tol(precision, 10))


@pytest.mark.parametrize("vx, collides", [(1.0, True), (0.0, False), (-1.0, False)])
def test_spheres_starting_exactly_touching(arch, vx, collides):
    """Touching at t = 0: approaching -> collide at once; at rest (zero relative
    velocity) or separating -> nothing happens; never a NaN."""
    r = 0.1
    x = np.array([[0.4, 0.5, 0.5], [0.6, 0.5, 0.5]])
    v = np.array([[vx, 0.0, 0.0], [0.0, 0.0, 0.0]])
    scene = ts.Scene.from_arrays(x, v, r, gravity=(0, 0, 0))
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(0.05)
    st = sim.state()
    assert _finite(st)
    assert sim.stats["pair_collisions"] == (1 if collides else 0)
    if collides:
        assert np.allclose(st.v[:, 0], [0.0, 1.0], atol=1e-14)
    assert sim.stats["max_overlap"] < 1e-12


def test_zero_relative_velocity_touching_pair_moves_together(arch):
    r = 0.1
    x = np.array([[0.3, 0.5, 0.5], [0.5, 0.5, 0.5]])
    v = np.full((2, 3), 0.3)
    sim = ts.Simulation(ts.Scene.from_arrays(x, v, r, gravity=(0, 0, 0), box=((0, 0, 0), (3, 3, 3))),
                        arch=arch)
    sim.advance(1.0)
    st = sim.state()
    assert _finite(st) and sim.stats["pair_collisions"] == 0
    assert np.allclose(st.x[1] - st.x[0], [0.2, 0.0, 0.0], atol=1e-14)


def test_coincident_centres_are_refused_at_set_up():
    with pytest.raises(ValueError, match="spheres 0 and 1"):
        ts.Scene.from_arrays([[0.5, 0.5, 0.5]] * 2, np.zeros((2, 3)), 0.1)


def test_heavy_intruder_mass_ratio_1e6_books_balance(arch):
    """One sphere 10^6 times heavier than the others in an elastic gas: energy and
    momentum (periodic) conserved to round-off."""
    scene = gas(300, packing=0.2, periodic=True, seed=2)
    mass = scene.mass.copy()
    mass[0] *= 1e6
    scene = scene.replace(mass=mass, v=np.where(np.arange(scene.n)[:, None] == 0, 0.0, scene.v))
    sim = ts.Simulation(scene, arch=arch)
    st0 = sim.state()
    sim.advance(3.0)
    st = sim.state()
    assert sim.stats["pair_collisions"] > 3 * scene.n
    e0, e1 = (ts.observe.total_energy(s, (0, 0, 0)) for s in (st0, st))
    assert abs(e1 / e0 - 1) < tol_for(sim, 1e-12, 1e2)
    p_scale = np.sqrt(2 * e0 * mass.sum())
    assert np.all(np.abs(ts.observe.momentum(st) - ts.observe.momentum(st0))
                  < tol_for(sim, 1e-12, 1e3) * p_scale)


def test_radius_ratio_10_books_balance(arch):
    """Ten large spheres among small ones ten times smaller (grid cell set by the
    largest): energy conserved, no overlap left, grid agrees with brute force."""
    rng = np.random.default_rng(5)
    big = np.array([[x, y, z] for x in (1.5, 4.5) for y in (1.5, 4.5) for z in (1.5, 4.5)])[:8]
    small = []
    while len(small) < 400:
        p = rng.uniform(0.15, 5.85, 3)
        if np.all(np.linalg.norm(big - p, axis=1) > 1.0 + 0.1 + 1e-3) and \
                all(np.linalg.norm(q - p) > 0.2 + 1e-3 for q in small):
            small.append(p)
    x = np.vstack([big, small])
    radius = np.r_[np.full(8, 1.0), np.full(len(small), 0.1)]
    v = rng.normal(size=x.shape)
    scene = ts.Scene.from_arrays(x, v, radius, box=((0, 0, 0), (6, 6, 6)), gravity=(0, 0, 0))
    sim = ts.Simulation(scene, arch=arch)
    e0 = ts.observe.total_energy(sim.state(), (0, 0, 0))
    sim.advance(2.0)
    st = sim.state()
    assert sim.stats["pair_collisions"] > 400
    assert abs(ts.observe.total_energy(st, (0, 0, 0)) / e0 - 1) < tol_for(sim, 1e-12, 1e2)
    assert sim.stats["max_overlap"] < 0.05
    brute = [(i, j) for i in range(scene.n) for j in range(i + 1, scene.n)
             if np.linalg.norm(st.x[i] - st.x[j]) < radius[i] + radius[j]]
    assert sim.grid_overlaps().shape[0] <= len(brute)


def test_very_fast_sphere_does_not_tunnel(arch):
    """One sphere 10^6 times faster than the rest: the adaptive step keeps it from
    passing through spheres or walls; energy conserved."""
    scene = gas(200, packing=0.2, periodic=False, seed=7, speed=1e-3)
    v = scene.v.copy()
    v[0] = [1e3, 0.7e3, 0.3e3]
    scene = scene.replace(v=v)
    sim = ts.Simulation(scene, arch=arch)
    e0 = ts.observe.total_energy(sim.state(), (0, 0, 0))
    sim.advance(0.02)
    st = sim.state()
    assert _finite(st)
    assert sim.stats["wall_collisions"] > 5 and sim.stats["pair_collisions"] > 5
    assert abs(ts.observe.total_energy(st, (0, 0, 0)) / e0 - 1) < tol_for(sim, 1e-12, 1e2)
    slack = tol_for(sim, 1e-12, 1e2) * np.abs(scene.box_hi).max()   # f32: of the coordinates
    assert np.all(st.x - st.radius[:, None] >= scene.box_lo - slack)
    assert np.all(st.x + st.radius[:, None] <= scene.box_hi + slack)
    d = np.linalg.norm(st.x[:, None] - st.x[None], axis=-1) + np.eye(scene.n) * 9
    assert np.min(d / (st.radius[:, None] + st.radius[None])) > 1 - 1e-6


def test_newtons_cradle_gives_the_sequential_answer(arch, precision):
    """Five touching balls, the first hits the row at v: the simultaneous contacts are
    resolved one after another (earliest first, then in sweep order), which for e = 1
    is the sequential-collision answer: the last ball leaves with v, the others stop."""
    r = 0.05
    x = np.array([[0.2 + 2 * r * k, 0.5, 0.5] for k in range(5)])
    x[0, 0] -= 0.05
    v = np.zeros((5, 3))
    v[0, 0] = 1.0
    scene = ts.Scene.from_arrays(x, v, r, gravity=(0, 0, 0))
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    sim.advance(0.1)
    st = sim.state()
    assert np.allclose(st.v[:4], 0.0, atol=tol(precision, 100))
    assert np.allclose(st.v[4], [1.0, 0.0, 0.0], atol=tol(precision, 100))
    assert sim.stats["pair_collisions"] == 4


def test_inelastic_collapse_does_not_stall(arch):
    """e = 0 and e = 0.1 in a dense gas without gravity: clusters of repeated
    collisions are cut by the collapse rule and the sweep limit; the run finishes
    with bounded work per step, energy never rises, overlaps stay small."""
    for e in (0.0, 0.1):
        scene = gas(500, packing=0.4, periodic=True, seed=3, restitution=e)
        sim = ts.Simulation(scene, arch=arch)
        e0 = ts.observe.kinetic_energy(sim.state())
        energies = []
        for _ in range(10):
            sim.advance(0.05)
            energies.append(ts.observe.kinetic_energy(sim.state()))
        assert np.all(np.diff([e0] + energies) <= tol_for(sim, 1e-12, 1e2) * e0)
        assert energies[-1] < 0.5 * e0
        assert sim.stats["sweeps"] <= sim.max_sweeps * sim.stats["steps"]
        assert sim.stats["max_overlap"] < 0.02
        assert _finite(sim.state())
        b = sim.energy_budget()
        assert abs(b["unaccounted"]) < tol_for(sim, 1e-9, 1e2) * e0


def test_fused_step_hands_over_to_kernels_after_a_rebuild(arch):
    """When a sphere moves farther than the grid's margin within a step (a dense
    inelastic gas at step_fraction 1), the fused step stops, the step goes on kernel
    by kernel after re-binning, and the result is the same bits as kernel by kernel."""
    scene = gas(300, packing=0.4, periodic=True, restitution=0.7, seed=1)
    stats = _fused_matches_kernel_by_kernel(arch, scene, lambda sim: 30 * sim.max_step(),
                                            step_fraction=1.0)
    assert stats["grid_rebuilds"] > 0


def test_slow_side_wall_and_ceiling_bounces_keep_their_restitution(arch, precision):
    """Under gravity only floor-like walls (gravity pressing the sphere into the wall)
    have an impact speed: a sphere meeting a side wall at 0.12 m/s and one reaching the
    ceiling at 0.05 m/s, both below the floor's impact speed, leave with e_w times their
    speed; a slow floor approach is a persistent contact and rests, its energy booked
    to the contact solver."""
    r, e_w, g = 0.05, 0.8, 9.81
    gap = 1e-3
    v_ceiling = 0.05                      # normal speed at the ceiling
    vz0 = np.sqrt(v_ceiling ** 2 + 2 * g * gap)
    x = [[1 - r - gap, 0.5, 0.5], [0.5, 0.2, 1 - r - gap], [0.2, 0.8, r + 0.2 * gap]]
    v = [[0.12, 0, 0], [0, 0, vz0], [0, 0, -0.05]]
    scene = ts.Scene.from_arrays(x, v, r, gravity=(0, 0, -g), restitution=0.5,
                                 wall_restitution=e_w)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    assert sim.rest_speed > 0.12          # all three impacts are slower than it
    sim.advance(0.02)                     # every sphere hits its wall within 0.01 s
    st = sim.state()
    assert st.v[0, 0] == pytest.approx(-e_w * 0.12, rel=tol(precision, 1e3))
    t_hit = (vz0 - v_ceiling) / g
    assert st.v[1, 2] == pytest.approx(-e_w * v_ceiling - g * (0.02 - t_hit),
                                       rel=tol(precision, 1e4))
    assert st.x[2, 2] == pytest.approx(r, abs=tol(precision, 10))   # rests on the floor
    assert sim.stats["wall_collisions"] >= 2
    assert sim.stats["energy_contacts"] > 0
