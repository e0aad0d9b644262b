"""The contact solver for persistent contacts (contacts/solver.py): resting columns and
piles, energy, momentum, determinism, warm starting, impacts into resting spheres.

Tolerances: overlaps relative to the diameter; speeds in m/s (f32 keeps about 7
digits of a position of order 0.1 m, so its speed and energy floors are wider).
"""
import math

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres import observe
from taichi_spheres.builders import ball_on_block, fcc_block
from taichi_spheres.config import Tuning
from conftest import brute_overlap

G = 9.81
R = 0.01


def _column(n, mass=None, gap=1e-4, e=0.5):
    """n spheres of radius R stacked on the floor, gaps ``gap`` [m] apart."""
    x = np.zeros((n, 3))
    x[:, :2] = 0.05
    x[:, 2] = R + (2 * R + gap) * np.arange(n)
    return ts.Scene.from_arrays(x, np.zeros((n, 3)), np.full(n, R), mass=mass,
                                box=((0, 0, 0), (0.1, 0.1, (2 * R + gap) * n + 0.1)),
                                gravity=(0, 0, -G), restitution=e, wall_restitution=e)


def _energies_by_step(sim, steps):
    """Total energy after each of ``steps`` steps [J]."""
    out = [sim.energy_budget()["current"]]
    for _ in range(steps):
        sim.advance(sim.max_step())
        out.append(sim.energy_budget()["current"])
    return np.array(out)


def _speed_floor(precision):
    return 1e-6 if precision == "f64" else 1e-3


@pytest.mark.parametrize("n", [20])
def test_column_settles_without_overlap_or_drift(arch, precision, n):
    sim = ts.Simulation(_column(n), arch=arch, precision=precision)
    sim.advance(2.0)
    st = sim.state()
    assert brute_overlap(st, sim.scene) <= 1e-4
    assert np.abs(st.v).max() <= _speed_floor(precision)
    z = st.x[:, 2].copy()
    sim.advance(10.0)                          # no drift over 10 s
    assert np.abs(sim.state().x[:, 2] - z).max() <= 1e-4 * 2 * R
    assert sim.stats["sweep_limit_hits"] == 0
    assert sim.last_step["contact_residual"] <= \
        sim.tuning.physics.contact_tolerance * sim.rest_speed


def test_fcc_block_settles_and_holds(arch):
    """1,000 spheres in an FCC block on the floor: settled within 1 s, then held for 2 s
    without drift, at rest and without overlap."""
    scene = fcc_block()
    assert scene.n == 1000
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(1.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= 1e-4
    x = st.x.copy()
    sim.advance(2.0)
    st = sim.state()
    assert np.abs(st.x - x).max() <= 1e-4 * 2 * R
    assert np.abs(st.v).max() <= 1e-6
    assert brute_overlap(st, scene) <= 1e-4
    assert sim.last_step["contact_iterations"] <= 5
    assert sim.stats["sweep_limit_hits"] == 0


def test_energy_stays_below_the_start_and_is_booked(arch):
    """Column landing from small gaps and an FCC block collapsing: at every step the
    total energy is below the initial one, and every joule is booked (impacts and
    contacts). (Step by step it can rise by the potential energy of an overlap the
    split impulse removes: docs/algorithm.md.)"""
    for scene in (_column(20), fcc_block(4)):
        sim = ts.Simulation(scene, arch=arch)
        e = _energies_by_step(sim, 150)
        assert e.max() <= e[0] * (1 + 1e-12)
        assert e[-1] < e[0]
        budget = sim.energy_budget()
        assert budget["contacts"] > 0
        assert abs(budget["unaccounted"]) <= 1e-9 * abs(budget["initial"])


def _heavy_on_light(ratio=1e3):
    """Column of 20 on the floor, the upper half ``ratio`` x heavier."""
    mass = np.full(20, 4.19e-3)
    mass[10:] *= ratio
    return _column(20, mass=mass)


def test_light_spheres_crushed_under_heavy_ones_stay_finite(arch):
    """Without shock propagation the sweeps cannot hold a column whose upper half is
    10^3 x heavier: the heavy spheres sink and press the light ones flat onto the floor
    until their centres meet (docs/algorithm.md, "Shock propagation"). A contact row
    whose spheres' centres coincide takes a fixed normal instead of 0/0: every
    position and speed stays finite, and the column ends below its start."""
    scene = _heavy_on_light()
    sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(shock_propagation="off"))
    sim.advance(1.0)
    st = sim.state()
    assert np.isfinite(st.x).all() and np.isfinite(st.v).all()
    assert st.x[:, 2].max() < scene.x[:, 2].max() - 0.05


def test_heavy_on_light_column_holds(arch, precision):
    """Upper half of a column of 20 10^3 x heavier (the sweeps alone need ~10^3 x more
    iterations here and let it sink; unequal masses get the shock propagation pass by
    default): the column settles with overlaps <= 1e-4 of a diameter, at rest, without
    drift over 10 s, and its energy never rises above the start."""
    scene = _heavy_on_light()
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    e = _energies_by_step(sim, 100)
    assert e.max() <= e[0] * (1 + 1e-12)
    sim.advance(2.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= _speed_floor(precision)
    z = st.x[:, 2].copy()
    sim.advance(10.0)
    st = sim.state()
    # f32 keeps ~7 digits of the top sphere's 0.4 m: its column settles ~3e-6 m in 10 s
    drift = 1e-4 if precision == "f64" else 1e-3
    assert np.abs(st.x[:, 2] - z).max() <= drift * 2 * R
    assert brute_overlap(st, scene) <= 1e-4


def test_over_relaxed_sweeps_hold_the_heavy_on_light_column(arch, precision):
    """Over-relaxation 1.8 (Rules.relaxation) on the column whose upper half is 10^3 x
    heavier: a solve stopped at its cap ends with plain sweeps (Rules.plain_sweeps), so
    the overshoot of the relaxed ones is not kept, and the column settles at rest
    without overlap, its energy never above the start; without those last plain sweeps
    it does not hold (overlaps above 1e-2 of a diameter, or a state that is no longer
    finite)."""
    scene = _heavy_on_light()
    worst = {}
    for plain in (10, 0):
        sim = ts.Simulation(scene, arch=arch, precision=precision,
                            tuning=Tuning().with_(relaxation=1.8, plain_sweeps=plain))
        e = _energies_by_step(sim, 100)
        sim.advance(2.0)
        st = sim.state()
        finite = bool(np.isfinite(st.x).all() and np.isfinite(st.v).all())
        worst[plain] = brute_overlap(st, scene) if finite else np.inf
        if plain:
            assert finite
            assert e.max() <= e[0] * (1 + 1e-12)
            assert np.abs(st.v).max() <= _speed_floor(precision)
    assert worst[10] <= 1e-4
    assert worst[0] > 1e-2


@pytest.mark.parametrize("name, value", [("relaxation", 2.0), ("relaxation", 0.0),
                                         ("solver_interleave", 0),
                                         ("frictional_interleave", 0),
                                         ("parallel_interleave", 0),
                                         ("sweeps_per_wait", 0),
                                         ("gpu_sweeps_per_wait", 0),
                                         ("contact_iterations", 0),
                                         ("position_iterations", 0), ("plain_sweeps", -1),
                                         ("position_extension", -1),
                                         ("shock_propagation", "always"),
                                         ("bounded_position_pass", 1)])
def test_solver_rules_out_of_range_name_the_field(name, value):
    """Tuning values the solver cannot run with are refused by name."""
    with pytest.raises(ValueError, match=f"tuning {name}"):
        Tuning().with_(**{name: value})


def test_shock_propagation_changes_nothing_where_the_sweeps_converge(arch):
    """A settled column of 20 (warm-started: one sweep per step leaves every row within
    tolerance): 0.5 s more from its checkpoint gives the same bits with and without
    the pass."""
    scene = _column(20)
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(2.0)
    settled = sim.checkpoint()
    out = []
    for shock in ("off", "on"):
        sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(shock_propagation=shock))
        sim.restore(settled)
        sim.advance(0.5)
        assert sim.last_step["contacts"] == 20
        out.append(observe.state_digest(sim.state(), sim.precision))
    assert out[0] == out[1]


def test_shock_propagation_takes_auto_on_or_off():
    """Rules.shock_propagation is one of "auto", "on", "off"; anything else is a
    ValueError naming the field."""
    assert Tuning().physics.shock_propagation == "auto"
    for bad in ("yes", True, 1):
        with pytest.raises(ValueError, match="shock_propagation"):
            Tuning().with_(shock_propagation=bad)


def test_shock_propagation_is_compiled_where_it_has_a_floor():
    """"auto" compiles the pass in for unequal masses under gravity with walls across
    it, "on" for equal masses too; never where gravity points along a periodic axis."""
    from taichi_spheres.contacts.shock import shock_compiled
    from taichi_spheres.state import Features
    heavy = _heavy_on_light()

    def compiled(scene, mode):
        return shock_compiled(Features.from_scene(scene, 0.0),
                              Tuning().with_(shock_propagation=mode).physics)

    assert compiled(heavy, "auto") and not compiled(heavy, "off")
    assert not compiled(_column(5), "auto") and compiled(_column(5), "on")
    chute = ts.Scene.from_arrays(heavy.x, heavy.v, heavy.radius, mass=heavy.mass,
                                 box=(heavy.box_lo, heavy.box_hi), gravity=(0, 0, -G),
                                 periodic=(False, False, True), restitution=0.5)
    assert not compiled(chute, "on")


def test_shock_propagation_same_bits_serial_and_parallel(arch):
    """The pass runs serially in both solver paths: one-launch and per-colour
    launches give the same state for a heavy-on-light column."""
    out = []
    for below in (3000, 0):
        sim = ts.Simulation(_heavy_on_light(), arch=arch, tuning=Tuning().with_(
            serial_heavy_below=below, serial_solver_below=below))
        sim.advance(0.5)
        out.append(observe.state_digest(sim.state(), sim.precision))
    assert out[0] == out[1]


@pytest.mark.parametrize("substeps", [False, True])
def test_a_sphere_at_rest_just_above_the_floor_settles_onto_it(arch, precision, substeps):
    """A sphere at rest 20 um above the floor (far less than the g h^2 / 2 ~ 1 mm its
    drift falls in a step): its floor row, which sees the drifted overlap, stops it,
    and the trapezoidal move would put it back where it started, every step; the
    solver lowers it onto the floor instead (ContactSolver.close_support_gaps), and it
    rests there touching, without overlap."""
    gap = 2e-5
    x = np.array([[0.05, 0.05, R + gap]])
    scene = ts.Scene.from_arrays(x, np.zeros((1, 3)), np.full(1, R),
                                 box=((0, 0, 0), (0.1, 0.1, 0.1)), gravity=(0, 0, -G),
                                 restitution=0.5, wall_restitution=0.5)
    sim = ts.Simulation(scene, arch=arch, precision=precision,
                        tuning=Tuning().with_(substeps=substeps))
    assert sim.max_step() ** 2 * G / 2 > 10 * gap
    energy = [sim.energy_budget()["current"]]
    for _ in range(5):
        sim.advance(sim.max_step())
        energy.append(sim.energy_budget()["current"])
    st = sim.state()
    tol = 1e-4 * 2 * R if precision == "f64" else 1e-3 * 2 * R
    assert -tol <= st.x[0, 2] - R <= tol
    assert np.abs(st.v).max() <= _speed_floor(precision)
    assert max(energy) <= energy[0] * (1 + 1e-12)


@pytest.mark.parametrize("shock, substeps", [
    ("off", False), ("on", False), ("off", True), ("on", True)])
def test_removing_the_support_under_a_warm_started_column(arch, shock, substeps):
    """A settled column of 10 whose bottom sphere is taken away (moved aside on the
    floor): the warm-started impulses between the others hold nothing up (they fall
    freely until they land), and the column settles again at rest without overlap,
    its energy never above that of the moment the support went (Box2D's Solver2D).
    Also in substeps (Rules.substeps)."""
    scene = _column(10)
    sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(shock_propagation=shock,
                                                                substeps=substeps))
    sim.advance(1.0)
    st = sim.state()
    x = st.x.copy()
    x[0] = (0.015, 0.015, R)                   # 0.05 m aside: touches nothing
    sim.set_state(x, st.v)
    e0 = sim.energy_budget()["current"]
    sim.advance(0.01)                          # a fall of 0.5 mm: nothing lands yet
    assert sim.stats["contacts"] > 0
    # free fall to 1e-4 of its speed (the sweeps stop within a tolerance every step)
    assert np.abs(sim.state().v[1:, 2] + G * 0.01).max() <= 1e-4 * G * 0.01
    e = _energies_by_step(sim, 100)
    assert e.max() <= e0 * (1 + 1e-12)
    sim.advance(2.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= 1e-6
    assert st.x[1:, 2].min() == pytest.approx(R, rel=1e-3)


@pytest.mark.parametrize("shock", ["off", "on"])
def test_overlap_recovery_moves_positions_not_velocities(arch, shock):
    """A column of 10 pressed together, every pair 5 % of a diameter into each other
    and the lowest sphere 5 % into the floor: the split impulse pushes the overlaps out
    without launching the spheres (a velocity-level push-out of the top sphere's 9.5 mm
    in one 14 ms step would be ~0.7 m/s; what is left upward is the sweeps' answer to
    the first step's fall), and within 1 s the column rests without overlap."""
    scene = _column(10)
    sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(shock_propagation=shock))
    x = scene.x.copy()
    x[:, 2] = 0.95 * R + 0.95 * 2 * R * np.arange(10)
    sim.set_state(x, np.zeros_like(x))
    upward = 0.0
    for _ in range(100):
        sim.advance(sim.max_step())
        upward = max(upward, float(sim.state().v[:, 2].max()))
    assert upward <= 2e-3          # ~1 mm/s: 300x below a push-out in one step
    sim.advance(1.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= 1e-6


def test_position_extension_removes_what_a_capped_pass_leaves(arch):
    """The pressed column of the last test with 3 position sweeps per step: the first
    step leaves most of its overlap; with Rules.position_extension the pass, stopped at
    its cap with more than half the overlap tolerance left, runs on until no row it
    meets overlaps by more than that, in positions only (the velocities keep their
    bits)."""
    scene = _column(10)
    x = scene.x.copy()
    x[:, 2] = 0.95 * R + 0.95 * 2 * R * np.arange(10)
    out = {}
    for extension in (0, 400):
        sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(
            position_iterations=3, position_extension=extension))
        sim.set_state(x, np.zeros_like(x))
        sim.advance(sim.max_step())
        out[extension] = (sim.last_step["max_overlap"], sim.last_step["position_iterations"],
                          sim.state().v)
    assert out[0][0] > 1e-2 and out[0][1] == 3
    assert out[400][0] <= 0.5e-4 and 3 < out[400][1] <= 403
    assert np.array_equal(out[0][2], out[400][2])


def test_solver_conserves_momentum_without_walls(arch):
    """Two touching clusters drifting into each other slowly in a periodic box with a
    rest speed and no gravity: impacts and contact rows keep momentum."""
    rng = np.random.default_rng(4)
    x = np.array([[0.05 + 2 * R * k, 0.1, 0.1] for k in range(6)])
    v = np.zeros_like(x)
    v[:3, 0] = 0.02
    v[3:, 0] = -0.01
    v += rng.normal(0, 1e-3, v.shape)
    mass = rng.uniform(0.5, 2.0, len(x))
    scene = ts.Scene.from_arrays(x, v, np.full(len(x), R), mass=mass,
                                 box=((0, 0, 0), (0.3, 0.2, 0.2)), periodic=(True,) * 3,
                                 gravity=(0, 0, 0), restitution=0.5, rest_speed=0.1)
    sim = ts.Simulation(scene, arch=arch)
    p0 = (mass[:, None] * v).sum(axis=0)
    sim.advance(0.5)
    st = sim.state()
    assert sim.stats["contacts"] > 0
    p1 = (st.mass[:, None] * st.v).sum(axis=0)
    assert np.allclose(p1, p0, rtol=0, atol=1e-14)


def test_sweep_rules_share_the_engine_and_keep_their_bits(arch, precision):
    """The sweep rules (config.SOLVER_VALUES: relaxation, sweep caps, plain sweeps,
    fewest scaled sweeps, position extension) are values the kernels read from fields: Simulations that
    differ only in them run on one engine, each under its own rules (a cap of 3
    velocity sweeps holds where the defaults run more), with the bits each gives alone,
    whichever ran in between."""
    capped = Tuning().with_(relaxation=1.0, contact_iterations=3, position_iterations=2,
                            plain_sweeps=1, min_scaled_sweeps=1, position_extension=5)
    assert capped.compiled() == Tuning().compiled()
    scene = fcc_block(3)

    def run(sims):
        """Digests after 8 chunks of 0.025 s, the Simulations alternated chunk by chunk
        (each bind loads its own rules), and the most velocity sweeps of a step of the
        first."""
        most = 0
        for _ in range(8):
            for sim in sims:
                sim.advance(0.025)
            most = max(most, sims[0].last_step["contact_iterations"])
        return [observe.state_digest(sim.state(), sim.precision) for sim in sims], most

    alone_capped = ts.Simulation(scene, arch=arch, precision=precision, tuning=capped)
    alone_default = ts.Simulation(scene, arch=arch, precision=precision)
    assert alone_capped.debug_view().engine is alone_default.debug_view().engine
    (capped_bits,), most_capped = run([alone_capped])
    (default_bits,), most_default = run([alone_default])
    together, _ = run([ts.Simulation(scene, arch=arch, precision=precision, tuning=capped),
                       ts.Simulation(scene, arch=arch, precision=precision)])
    assert together == [capped_bits, default_bits] and capped_bits != default_bits
    assert 0 < most_capped <= 3 < most_default


# the bounded position pass compiles engine variants of its own: behind --slow (the
# capped and scaled cases run on the plain case's engines: the caps are field values)
@pytest.mark.parametrize("case", [
    "fcc block", "odd periodic colours, plain sweeps", "fcc block, 15 sweeps",
    pytest.param("fcc block, 15 sweeps, bounded position pass", marks=pytest.mark.slow),
    "fcc block, 15 sweeps scaled with the step", "fcc block, 5 position sweeps extended"])
def test_serial_and_parallel_solver_give_the_same_bits(arch, case):
    """The one-launch serial solver and the per-colour parallel launches (forced with
    serial_heavy_below = serial_solver_below = 0), each with one cell per sweep loop
    iteration or several interleaved (Performance.solver_interleave and
    parallel_interleave), and with one wait per sweep or per batch of several
    (sweeps_per_wait, gpu_sweeps_per_wait: 4, which a cap of 15 does not divide, and
    7), give the same
    state: an FCC block in a box (the default over-relaxed sweeps and their plain last
    sweeps), and layers on a grid with a third colour on two periodic axes (plain
    sweeps, relaxation 1); with a cap of 15 sweeps, 10 of them plain, solves also stop
    inside the plain ones (and the bounded position pass sums its energies in the same
    order on both paths), and with caps scaled with each step's length
    (Rules.step_scaled_sweeps) both paths take the same caps; with 5 position sweeps
    extended (Rules.position_extension) both run the same extra sweeps."""
    scene, seconds = ((_periodic_layer_scene(), 0.2) if case.startswith("odd periodic")
                      else (fcc_block(4), 0.3))
    rules = dict(relaxation=1.0) if "plain" in case else {}
    if "15 sweeps" in case:
        rules.update(contact_iterations=15, position_iterations=15)
    if "bounded" in case:      # low caps, where the bound scales the position pass
        rules.update(bounded_position_pass=True)
    if "scaled" in case:       # caps that change from step to step
        rules.update(step_scaled_sweeps=True, min_scaled_sweeps=2)
    if "extended" in case:     # a cap that the pressed block's first passes overrun
        rules.update(position_iterations=5, position_extension=40)
    out, sweeps = [], []
    # (below, interleave, batch): both paths, then the interleaving and batching
    # variants where they meet something of their own (every variant on the plain FCC
    # block; on the third colour an interleaving of 3, whose last group of a colour is
    # partial where 3 does not divide its cells, and a batch; the capped solves a
    # batch; the bounded pass only the two paths' sums)
    configs = ((3000, 8, 1), (0, 8, 1))
    if case == "fcc block":
        configs += ((0, 8, 4), (3000, 1, 1), (0, 3, 1), (0, 1, 7))
    elif case.startswith("odd periodic"):
        configs += ((0, 3, 1), (0, 1, 7))
    elif "bounded" not in case:
        configs += ((0, 8, 4),)     # a batch of 4 does not divide the cap of 15 (or 5)
    solvers = {}
    for below, interleave, batch in configs:
        sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(
            serial_heavy_below=below, serial_solver_below=below, solver_interleave=interleave,
            parallel_interleave=interleave, sweeps_per_wait=batch,
            gpu_sweeps_per_wait=batch, **rules))
        if "extended" in case:     # layers pressed 2 % of a diameter into each other
            x = scene.x.copy()
            x[:, 2] = R + 0.98 * (x[:, 2] - R)
            sim.set_state(x, scene.v)
        counts = []
        quiet = ((sim.tuning.physics.contact_margin - 1) * sim.step_fraction *
                 float(scene.radius.min()) / sim.rest_speed)
        while sim.time < seconds:
            h = sim.max_step()
            if "scaled" in case:       # steps of 0.2, 0.5 and 1 quiet step: caps 3, 8, 15
                h = min(h, (0.2, 0.5, 1.0)[len(counts) % 3] * quiet)
            sim.advance(h)
            counts.append((sim.last_step["contact_iterations"],
                           sim.last_step["position_iterations"]))
        assert sim.stats["contacts"] > 0
        out.append(observe.state_digest(sim.state(), sim.precision))
        sweeps.append(counts)
        solvers.setdefault(below, set()).add(sim.debug_view().solver)
    # the configurations of one path share its engine; on the CPU each interleaving of
    # the parallel path launched sweep kernels of its own (ContactSolver._sweep; the
    # engine may hold an earlier case's too: the sweep caps are values in fields)
    assert all(len(same) == 1 for same in solvers.values())
    parallel = {interleave for below, interleave, _ in configs if below == 0}
    if arch == "cpu":
        (solver,) = solvers[0]
        assert parallel <= {key[3] for key in solver._sweeps}
    if "scaled" in case:   # the scaled caps bound solves (ceil(15 x 0.2) is 3, or 4 by round-off)
        assert sweeps[0][0][0] > 4      # but not the first, cold one (no warm start)
        assert any(vel == 3 for vel, _ in sweeps[0][3::3])
        assert all(vel <= 4 for vel, _ in sweeps[0][3::3])
    if "extended" in case:
        assert any(pos > 5 for _, pos in sweeps[0])
    assert len(set(out)) == 1
    assert all(counts == sweeps[0] for counts in sweeps)
    if case == "fcc block, 15 sweeps":   # some solves stopped inside the plain last sweeps
        assert any(5 < n < 15 for step in sweeps[0] for n in step)


def test_step_scaled_sweeps_follow_the_step_length(arch, precision):
    """Rules.step_scaled_sweeps: an FCC block, every sphere pushed down at half the
    impact speed before each step (a squeeze each solve must stop), stepped at half and
    then a twentieth of a quiet bed's step h_q = (contact_margin - 1) D / impact speed.
    The first solve is cold (no warm start) and keeps the full caps; each later one
    runs at most ceil(cap h / h_q) velocity and position sweeps (at least
    min_scaled_sweeps), and some reach that bound (with the full caps they take ~50);
    the block then settles without overlap. (Rules.position_extension, not scaled,
    is off here: its sweeps come on top of the cap.)"""
    tuning = Tuning().with_(step_scaled_sweeps=True, min_scaled_sweeps=3,
                            position_extension=0)
    scene = fcc_block(4)
    sim = ts.Simulation(scene, arch=arch, precision=precision, tuning=tuning)
    rules = tuning.physics
    quiet = (rules.contact_margin - 1) * sim.step_fraction * float(scene.radius.min()) \
        / sim.rest_speed
    push = np.array([0.0, 0.0, -0.5 * sim.rest_speed])

    def squeezed_step(share):
        st = sim.state()
        sim.set_state(st.x, st.v + push)
        sim.advance(share * quiet)
        return sim.last_step

    assert squeezed_step(0.5)["contact_iterations"] > math.ceil(0.5 * rules.contact_iterations)
    reached = False
    for share in (0.5, 0.05):
        for _ in range(6):
            step = squeezed_step(share)
            assert step["contacts"] > 0
            for used, cap in ((step["contact_iterations"], rules.contact_iterations),
                              (step["position_iterations"], rules.position_iterations)):
                bound = max(math.ceil(cap * share * (1 + 1e-9)), 3)
                assert 1 <= used <= bound
                reached |= used >= bound - 1 and bound > 3
    assert reached
    sim.advance(1.0)
    st = sim.state()
    assert brute_overlap(st, scene) <= 1e-4
    assert np.abs(st.v).max() <= _speed_floor(precision)


def test_warm_start_cuts_iterations(arch):
    """Settled column of 20: velocity sweeps per step with warm start are at most 1/5
    of those without."""
    scene = _column(20)
    its = {}
    for warm in (True, False):
        sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(warm_start=warm))
        sim.advance(1.0)
        before = sim.stats["contact_iterations"], sim.stats["contact_steps"]
        sim.advance(0.5)
        its[warm] = (sim.stats["contact_iterations"] - before[0]) / \
            (sim.stats["contact_steps"] - before[1])
    assert its[True] <= its[False] / 5


def test_newtons_cradle_touching_at_rest(arch, precision):
    """Five balls touching at rest, e = 1, struck by a sixth: the last leaves with the
    striker's speed, the others stay at rest (to round-off)."""
    n = 5
    x = np.array([[0.2 + 2 * R * k, 0.1, 0.1] for k in range(n)] + [[0.1, 0.1, 0.1]])
    v = np.zeros_like(x)
    v[-1, 0] = 1.0
    scene = ts.Scene.from_arrays(x, v, np.full(n + 1, R), box=((0, 0, 0), (0.6, 0.2, 0.2)),
                                 gravity=(0, 0, 0), restitution=1.0)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    sim.advance(0.1)
    st = sim.state()
    tol = 1e-12 if precision == "f64" else 1e-5
    assert st.v[n - 1, 0] == pytest.approx(1.0, abs=tol)
    assert np.abs(st.v[:n - 1]).max() <= tol and abs(st.v[n, 0]) <= tol


@pytest.mark.parametrize("shock", ["off", "auto"])
def test_heavy_ball_dropped_onto_a_settled_bed(arch, shock):
    """A ball 8x heavier dropped onto a settled FCC block (unequal masses: "auto" runs
    the shock propagation pass): energy never grows, overlaps stay within 1e-4 of a diameter, nothing
    passes through the floor, all comes to rest. The settled block starts with overlaps
    of up to ``ov0`` of a diameter, which the split impulse removes: that may lift each
    of its layers by ov0 diameters, and the energy may exceed the start by that
    potential energy (docs/algorithm.md)."""
    scene = fcc_block(4)
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(1.0)
    st = sim.state()
    layers = np.unique(np.round(st.x[:, 2] / R, 1)).size
    lift = st.mass.sum() * G * layers * brute_overlap(st, scene) * 2 * R     # [J]
    bed, x, v = ball_on_block(scene, st, ratio=8.0, height=0.05, speed=1.0)
    sim = ts.Simulation(bed, arch=arch, tuning=Tuning().with_(shock_propagation=shock))
    sim.set_state(x, v)
    sim.initial_energy = sim.energy_budget()["current"]
    e = _energies_by_step(sim, 200)
    assert e.max() <= e[0] * (1 + 1e-12) + lift
    sim.advance(2.0)
    st = sim.state()
    assert brute_overlap(st, bed) <= 1e-4
    assert st.x[:, 2].min() >= R * (1 - 1e-4)
    assert np.abs(st.v).max() <= 1e-3
    assert sim.stats["pair_collisions"] > 0 and sim.stats["contacts"] > 0


def test_bounded_warm_start_takes_a_mode():
    """Rules.bounded_warm_start is "auto", "on" or "off"; anything else is a
    ValueError naming it (True included: the modes are words, like shock_propagation)."""
    for mode in ("auto", "on", "off"):
        assert Tuning().with_(bounded_warm_start=mode).physics.bounded_warm_start == mode
    with pytest.raises(ValueError, match="bounded_warm_start"):
        Tuning().with_(bounded_warm_start=True)


def test_bounded_position_pass_never_raises_the_energy_of_a_step(arch):
    """With Rules.bounded_position_pass the position pass lifts no more than the step's
    solve took out (contacts/position_energy.py): the heavy ball landing on the block
    with few sweeps, where the split impulse otherwise lifts the block by up to 1e-3 of
    the ball's impact energy in a step, and the block settling from its lattice at 60
    velocity sweeps, whose energy otherwise rises above its start: no step raises the
    total energy beyond round-off."""
    tuning = Tuning().with_(contact_iterations=40, position_iterations=40,
                            bounded_position_pass=True)
    block = fcc_block(4)
    sim = ts.Simulation(block, arch=arch, tuning=tuning.with_(contact_iterations=60))
    e = _energies_by_step(sim, 150)
    assert np.diff(e).max() <= 1e-12 * e[0] and e[-1] < e[0]
    sim.advance(1.0)
    bed, x, v = ball_on_block(block, sim.state(), ratio=8.0, height=0.05, speed=1.0)
    sim = ts.Simulation(bed, arch=arch, tuning=tuning)
    sim.set_state(x, v)
    e = _energies_by_step(sim, 120)
    assert sim.stats["pair_collisions"] > 0 and sim.stats["contacts"] > 0
    assert np.diff(e).max() <= 1e-12 * abs(e).max()


def test_bounded_position_pass_keeps_the_overlaps_a_resting_scene_starts_with(arch):
    """The bound's other side: the column of the overlap-recovery test, pressed 5 % into
    itself at rest, has no energy a solve takes out, so with Rules.bounded_position_pass
    its overlaps stay (without it they are gone: the test above) and nothing moves."""
    scene = _column(10)
    sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(bounded_position_pass=True))
    x = scene.x.copy()
    x[:, 2] = 0.95 * R + 0.95 * 2 * R * np.arange(10)
    sim.set_state(x, np.zeros_like(x))
    sim.advance(0.2)
    assert brute_overlap(sim.state(), scene) == pytest.approx(0.05, rel=1e-3)
    assert np.abs(sim.state().x - x).max() <= 1e-6 * R


@pytest.mark.parametrize("bounded, substeps", [
    pytest.param("auto", False, marks=pytest.mark.slow), ("off", False), ("auto", True)])
def test_bounded_warm_start_adds_no_energy_after_a_heavy_impact(arch, bounded, substeps):
    """The heavy ball of the test above, solved with few over-relaxed sweeps (relaxation
    1.8, 40 velocity and 40 position sweeps), where the step after the impact starts
    from the impulses that stopped the ball and stops at its cap
    (contacts/warm_energy.py). With the warm start bounded the total energy never grows
    in a step by more than 1e-3 of the ball's kinetic energy at impact (what is left:
    the split impulse lifting the block off the floor) and the solver counts the steps
    it scaled; the plain warm start grows it by more than a tenth of that energy in one
    step (what the bound is for). The bound holds as well in substeps (Rules.substeps:
    the solver's steps are longer, and the position pass also separates spheres the
    solve's position update pushed into a neighbour about to hit them, which lifts a
    little more: 2e-3 of the impact energy at most)."""
    tuning = Tuning().with_(relaxation=1.8, contact_iterations=40, position_iterations=40,
                            bounded_warm_start=bounded, substeps=substeps)
    scene = fcc_block(4)
    sim = ts.Simulation(scene, arch=arch, tuning=tuning)
    sim.advance(1.0)
    bed, x, v = ball_on_block(scene, sim.state(), ratio=8.0, height=0.05, speed=1.0)
    sim = ts.Simulation(bed, arch=arch, tuning=tuning)
    sim.set_state(x, v)
    impact = 0.5 * bed.mass[-1] * (1.0 + 2 * G * (0.05 - 2 * R))     # [J]
    growth = np.diff(_energies_by_step(sim, 120)).max()
    assert sim.stats["pair_collisions"] > 0
    if bounded == "auto":     # no friction: on
        assert growth <= (2e-3 if substeps else 1e-3) * impact
        assert sim.stats["warm_starts_scaled"] > 0
    else:
        assert growth > 0.1 * impact
        assert sim.stats["warm_starts_scaled"] == 0


def _periodic_layer_scene(layers=8):
    """Touching layers of 3 x 3 spheres on the floor of a box periodic on x and y, 3
    grid cells wide on each (the grid's only odd periodic count: 3 colours)."""
    side = 0.08
    g = (np.arange(3) + 0.5) * side / 3
    xy = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    x = np.vstack([np.c_[xy, np.full(len(xy), R + (2 * R + 1e-6) * z)] for z in range(layers)])
    return ts.Scene.from_arrays(x, np.zeros_like(x), np.full(len(x), R),
                                box=((0, 0, 0), (side, side, 0.2)),
                                periodic=(True, True, False), gravity=(0, 0, -G),
                                restitution=0.5)


@pytest.mark.parametrize("parallel", [False, True])
def test_active_cells_list_each_row_owner_once_under_its_colour(arch, parallel):
    """pgs.list_active_cells (parallel count and placement) lists every cell that owns
    rows exactly once, under the colour GridGeometry.colours gives it, with odd cell
    counts on periodic axes (a third colour there) and several cells per colour; a
    serial solver lists them in linear order."""
    below = 0 if parallel else 3000
    sim = ts.Simulation(_periodic_layer_scene(), arch=arch, tuning=Tuning().with_(
        serial_heavy_below=below, serial_solver_below=below))
    sim.advance(sim.max_step())
    parts = sim.debug_view()
    solver, geom = parts.solver, parts.grid.geom
    assert len(geom.axis_colours(0)) == len(geom.axis_colours(1)) == 3   # odd, periodic
    start = solver.cell_start.to_numpy()[:geom.n_cells + 1]
    owners = np.flatnonzero(np.diff(start) > 0).tolist()
    listed = solver.active_cells.to_numpy()
    bounds = solver.colour_active.to_numpy()
    seen, most = [], 0
    for colour, spec in enumerate(geom.colours):
        cells = listed[bounds[colour]:bounds[colour + 1]].tolist()
        members = {int(np.ravel_multi_index(c, geom.dims)) for c in geom.colour_cells(spec)}
        assert set(cells) <= members, f"colour {colour} lists a cell of another colour"
        if solver.serial:
            assert cells == sorted(cells)
        seen += cells
        most = max(most, len(cells))
    assert most >= 2
    assert sorted(seen) == sorted(owners)


def _small_pour():
    """scenes/pour.toml scaled down: 150 spheres (r = 12 mm) poured into a box 0.2 m
    wide, e = 0.5."""
    import os
    import tomllib
    from taichi_spheres.scenefile import scene_from_dict
    with open(os.path.join(os.path.dirname(__file__), "..", "scenes", "pour.toml"), "rb") as fh:
        data = tomllib.load(fh)
    data["box"]["hi"] = [0.2, 0.2, 1.0]
    data["pour"][0].update(count=150, hi=[0.15, 0.15, 1.0])
    return scene_from_dict(data, source="small pour")


@pytest.mark.parametrize("substeps", [False, True])
def test_max_overlap_counts_pairs_and_walls_without_rows(arch, precision, substeps):
    """last_step["max_overlap"] is the largest overlap after the step over every pair
    and wall, not only over the solver's rows: in a pour's landing a solve's position
    update pushes spheres it stopped into neighbours and walls about to hit them
    (impacts to come, which have no rows), by up to 8.7e-4 of a diameter here (2.6e-3
    before held spheres were lowered onto their supports); the rows alone had
    missed such overlaps. The brute-force overlap after every step is never above what the
    step reports. With substeps those impacts to come have position-only rows, which
    keep such overlaps below 1e-3."""
    scene = _small_pour()
    sim = ts.Simulation(scene, arch=arch, precision=precision,
                        tuning=Tuning().with_(substeps=substeps))
    worst, under = 0.0, 0.0
    while sim.time < 0.45:
        sim.step_toward(0.45)
        brute = brute_overlap(sim.state(), scene)
        worst = max(worst, brute)
        under = max(under, brute - sim.last_step["max_overlap"])
    assert worst < 1e-3 if substeps else worst > 5e-4
    assert under <= (1e-12 if precision == "f64" else 1e-5)
    assert sim.stats["max_overlap"] >= worst - (1e-12 if precision == "f64" else 1e-5)


def test_staged_solve_keeps_the_bits_of_one_launch(arch):
    """Performance.staged_solve launches the serial solve one kernel per stage
    (contacts/solver.py SOLVE_STAGES, for profiles): the same state and counters as
    the one launch, on the same engine (CPU: a GPU's solve is never serial)."""
    if arch != "cpu":
        pytest.skip("the serial solve runs on the CPU")
    scene = fcc_block(3)
    runs = []
    for staged in (False, True):
        sim = ts.Simulation(scene, arch=arch, tuning=Tuning().with_(staged_solve=staged))
        sim.advance(0.1)
        runs.append((observe.state_digest(sim.state(), sim.precision), sim.stats["contacts"],
                     sim.stats["contact_iterations"], sim.debug_view().engine))
    assert runs[0][:3] == runs[1][:3] and runs[0][1] > 0
    assert runs[0][3] is runs[1][3]
