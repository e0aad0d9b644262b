"""Many-body invariants: elastic gases conserve energy and momentum, runs are
bit-for-bit reproducible, steps land on requested times, features compile out."""
import dataclasses

import numpy as np
import pytest
import taichi as ti

import taichi_spheres as ts
from taichi_spheres.builders import gas, same_bits_scene
from conftest import assert_same_counters, tol, tol_for


def _invariants(st, gravity=(0, 0, 0)):
    return ts.observe.total_energy(st, gravity), ts.observe.momentum(st)


@pytest.mark.parametrize("periodic", [True, False])
def test_elastic_gas_conserves_energy_and_momentum(arch, precision, periodic):
    scene = gas(1000, packing=0.3, periodic=periodic, seed=1)
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    st0 = sim.state()
    e0, p0 = _invariants(st0)
    sim.advance(4.0)
    st = sim.state()
    e1, p1 = _invariants(st)
    stats = sim.stats
    assert stats["pair_collisions"] > 10 * scene.n, "needs many collisions per sphere"
    assert stats["unresolved"] == 0
    # energy: each collision conserves |v|^2 to round-off; errors add up like a random walk
    rel = abs(e1 / e0 - 1)
    assert rel < tol(precision, 2e4 if precision == "f64" else 2e2), rel
    if precision == "f64":
        assert rel < 1e-12
    if periodic:
        p_scale = np.sqrt(2 * e0 * scene.mass.sum())     # sum m |v| scale
        assert np.all(np.abs(p1 - p0) < tol(precision, 1e3) * p_scale), p1 - p0
    else:
        assert stats["wall_collisions"] > 0
    # nothing left overlapping more than the out-of-order error of a step
    assert stats["max_overlap"] < 0.05
    # every sphere inside the box
    lo, hi = scene.box_lo, scene.box_hi
    if not periodic:
        slack = tol(precision, 1e3) * (hi - lo)
        assert np.all(st.x - st.radius[:, None] >= lo - slack)
        assert np.all(st.x + st.radius[:, None] <= hi + slack)


def test_unequal_masses_and_radii_conserve_energy(arch):
    scene = gas(500, packing=0.12, periodic=True, seed=4, polydispersity=0.5)
    rng = np.random.default_rng(0)
    mass = scene.mass * rng.uniform(0.1, 10.0, scene.n)
    scene = scene.replace(mass=mass)
    sim = ts.Simulation(scene, arch=arch)
    assert not sim.features.equal_masses and not sim.features.equal_radii
    e0, p0 = _invariants(sim.state())
    sim.advance(3.0)
    e1, p1 = _invariants(sim.state())
    assert sim.stats["pair_collisions"] > 5 * scene.n
    assert abs(e1 / e0 - 1) < tol_for(sim, 1e-12, 2e2)
    p_scale = np.sqrt(2 * e0 * mass.sum())
    assert np.all(np.abs(p1 - p0) < tol_for(sim, 1e-12, 1e3) * p_scale)


def test_same_scene_gives_identical_bits(arch):
    scene = gas(1500, packing=0.35, periodic=(True, False, True), seed=7, restitution=0.9,
                gravity=(0, 0, -2.0), wall_restitution=0.8)
    runs = []
    for _ in range(2):
        sim = ts.Simulation(scene, arch=arch)
        sim.advance(0.4)
        st = sim.state()
        runs.append((st.x, st.v, sim.stats))
    assert runs[0][2]["pair_collisions"] > 500
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    # on a GPU the energy books and the virial are sums of float atomics from parallel
    # threads, added in the order the threads come: equal to round-off
    assert_same_counters(runs[0][2], runs[1][2], sim)


@pytest.mark.own_runtime
def test_bits_do_not_depend_on_thread_count(arch):
    if arch != "cpu":
        pytest.skip("thread count is a CPU setting")
    scene = gas(4000, packing=0.3, periodic=True, seed=2)   # large enough for parallel loops
    out = []
    # (2 first: a runtime with Taichi's default count on 2 cores is kept)
    for threads in (2, 1):
        sim = ts.Simulation(scene, arch=arch, threads=threads)
        sim.advance(0.3)
        out.append(sim.state())
    assert np.array_equal(out[0].x, out[1].x) and np.array_equal(out[0].v, out[1].v)


def test_steps_land_exactly_on_requested_times(arch):
    sim = ts.Simulation(gas(200, periodic=True), arch=arch)
    for k in range(1, 6):
        sim.advance_to(k / 30.0)
        assert sim.time == k / 30.0
    sim.advance(0.0)
    assert sim.time == 5 / 30.0
    steps = sim.stats["steps"]
    assert steps > 5
    with pytest.raises(ValueError):
        sim.advance(-1.0)
    with pytest.raises(ValueError):
        sim.advance(float("nan"))


def test_step_toward_takes_the_steps_of_advance_to(arch):
    """A loop of step_toward(t) takes advance_to(t)'s steps (same count, same bits),
    lands on t, returns each step's length and 0 once there, and refuses a time in the
    past or not finite."""
    scene = same_bits_scene(200)
    whole = ts.Simulation(scene, arch=arch)
    whole.advance_to(0.05)
    stepped = ts.Simulation(scene, arch=arch)
    lengths = []
    while stepped.time < 0.05:
        lengths.append(stepped.step_toward(0.05))
    assert stepped.time == 0.05
    assert len(lengths) == whole.stats["steps"] == stepped.stats["steps"]
    assert abs(sum(lengths) - 0.05) <= 1e-12
    assert lengths[-1] == stepped.last_step["h"]
    assert ts.observe.state_digest(stepped.state(), stepped.precision) == \
        ts.observe.state_digest(whole.state(), whole.precision)
    assert stepped.step_toward(0.05) == 0.0
    for bad in (0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="cannot step toward"):
            stepped.step_toward(bad)


def test_adaptive_step_bounds_displacement(arch):
    """No sphere moves more than step_fraction * r_min in one free-flight step."""
    scene = gas(300, packing=0.1, periodic=False, seed=5, gravity=(0, 0, -9.81),
                polydispersity=0.5)
    sim = ts.Simulation(scene, arch=arch, step_fraction=0.05)
    for _ in range(20):
        before = sim.state()
        h = sim.max_step()
        v, g = before.v, scene.gravity
        disp = np.linalg.norm(v * h + 0.5 * g * h * h, axis=1)
        assert disp.max() <= 0.05 * scene.radius.min() * (1 + 1e-12)
        sim.step(h)


def test_features_compiled_in_only_when_needed(arch):
    plain = ts.Simulation(gas(100, periodic=True), arch=arch).features
    assert not plain.gravity and not plain.walls and plain.equal_radii and plain.equal_masses
    assert plain.elastic and plain.elastic_walls
    rich = ts.Simulation(gas(100, packing=0.1, periodic=False, gravity=(0, 0, -1), restitution=0.5,
                             wall_restitution=0.7, polydispersity=0.3), arch=arch)
    f = rich.features
    assert f.gravity_axes == (False, False, True) and f.wall_axes == (True, True, True)
    assert not f.equal_radii and not f.equal_masses and not f.elastic and not f.elastic_walls
    state = rich.debug_view().state
    assert state.radius is not None and state.inv_mass is not None
    assert f.contacts and rich.debug_view().solver is not None and state.loaded is not None
    other = ts.Simulation(gas(100), arch=arch).debug_view()
    assert other.state.radius is None and other.solver is None and other.state.loaded is None


def test_compiled_in_restitution_with_e_1_stays_elastic(arch):
    """Every feature compiled in (compile_all) on a dense elastic gas where spheres collide
    several times per step: e = 1 read at run time must keep the collisions elastic (the
    collapse rule for inelastic clusters must not apply), energy to round-off."""
    scene = gas(500, packing=0.45, periodic=True, seed=4, speed=3.0)
    sim = ts.Simulation(scene, arch=arch, compile_all=True, step_fraction=0.3)
    e0 = ts.observe.kinetic_energy(sim.state())
    sim.advance(0.5)
    assert sim.stats["multi_collision_spheres"] > 1000
    precision = sim.precision
    assert abs(ts.observe.kinetic_energy(sim.state()) / e0 - 1) < tol(precision, 1e4)


@pytest.mark.own_runtime
def test_stale_simulation_refuses_to_run(arch):
    sim = ts.Simulation(gas(50, periodic=True), arch=arch, precision="f64")
    ts.Simulation(gas(50, periodic=True), arch=arch, precision="f32")   # re-initialises
    with pytest.raises(RuntimeError, match="re-initialised"):
        sim.advance(0.1)


@pytest.mark.own_runtime
def test_asking_for_the_default_thread_count_keeps_the_runtime(arch):
    """A CPU runtime started without a thread count has Taichi's default; a Simulation
    that asks for that count runs on it, and earlier Simulations stay usable."""
    from taichi_spheres import runtime
    if arch != "cpu":
        pytest.skip("thread counts are a CPU setting")
    runtime.ensure(arch, "f32")
    default = runtime.ensure(arch, "f64")      # re-initialised without a thread count
    assert default.threads == ti.lang.impl.current_cfg().cpu_max_num_threads >= 1
    sim = ts.Simulation(gas(50, periodic=True), arch=arch, precision="f64")
    other = ts.Simulation(gas(50, periodic=True), arch=arch, precision="f64",
                          threads=default.threads)
    assert other.runtime is default and sim.runtime is default
    sim.advance(0.01)
    assert sim.stats["steps"] > 0


@pytest.mark.own_runtime
def test_compile_modes_give_the_same_bits(arch):
    """runtime.COMPILE_MODES change how long kernels take to compile and run, never the
    results: the same-bits reference scene (inelastic, walls, gravity, unequal radii
    and masses; tests/test_same_bits.py) ends in the stored bits in the compile mode
    the suite does not run in, as test_same_bits checks them in the one it runs in. A
    CPU promise: Taichi 1.7 compiles CUDA kernels with LLVM's unsafe-fp-math on
    whatever fast_math says (runtime.FAST_MATH), so which multiply-adds fuse there
    follows the code's shape, which the modes change."""
    from taichi_spheres import runtime
    from taichi_spheres.builders import same_bits_scene
    from test_same_bits import STORED
    if arch != "cpu":
        pytest.skip("same bits across compile modes is a CPU promise (runtime.FAST_MATH)")
    case = STORED["small"]
    suite_mode = runtime.compile_mode_from_env()
    (other,) = set(runtime.COMPILE_MODES) - {suite_mode}
    try:
        runtime.ensure(arch, "f64", compile=other)
        sim = ts.Simulation(same_bits_scene(case["n"]), arch=arch)
        assert sim.runtime.compile == other
        sim.advance(case["duration"])
        assert sim.stats["pair_collisions"] > 1000
        end = sim.state()
    finally:
        runtime.ensure(arch, "f64", compile=suite_mode)
    assert ts.observe.state_digest(end, "f64") == case["digests"]["f64"]


def test_compile_mode_choices(monkeypatch):
    from taichi_spheres import runtime
    from taichi_spheres.cli import AUTO_FAST_BELOW, compile_mode
    monkeypatch.setenv(runtime.COMPILE_ENV, "quick")
    with pytest.raises(ValueError, match=runtime.COMPILE_ENV):
        runtime.compile_mode_from_env()
    with pytest.raises(ValueError, match="compile"):
        runtime.ensure("cpu", compile="quick")
    assert compile_mode("optimized", 10) == "optimized"
    monkeypatch.setenv(runtime.COMPILE_ENV, "optimized")
    assert compile_mode("auto", 10) == "optimized"
    monkeypatch.delenv(runtime.COMPILE_ENV)
    assert runtime.compile_mode_from_env() == "optimized"
    assert compile_mode("auto", AUTO_FAST_BELOW - 1) == "fast"
    assert compile_mode("auto", AUTO_FAST_BELOW) == "optimized"


def test_loop_probe_passes_on_this_arch(arch):
    """The arch under test runs the grid walks' loop pattern (integer atomics in a loop
    over rows in a parallel loop) correctly: every visit counted, once."""
    from taichi_spheres import runtime
    runtime.ensure(arch)
    outer, rows, per_row = runtime.PROBE_SHAPE
    assert runtime.probe_loops() == (outer * rows * per_row, outer * rows * per_row)


@pytest.mark.own_runtime
def test_a_driver_failing_the_loop_probe_is_refused(arch):
    """A backend that drops visits in the probe (as Mesa's lavapipe 22 does) gets a
    RuntimeError that says what is wrong and what to use instead, not a simulation
    that silently misses collisions; Taichi is reset, and the next ensure starts it
    again."""
    from taichi_spheres import runtime
    runtime.ensure(arch)
    with pytest.raises(RuntimeError, match=r"counted 8 of 40.*miss collisions.*arch='cpu'"):
        runtime.refuse_broken_loops("vulkan", "vulkan", (8, 40))
    sim = ts.Simulation(gas(10, packing=0.05, periodic=True), arch=arch)
    sim.advance(0.01)
    runtime.refuse_broken_loops("vulkan", "vulkan", (40, 40))   # passes: no error
    sim.advance(0.01)


def test_bad_simulation_arguments(arch):
    scene = gas(10, packing=0.05, periodic=True)
    with pytest.raises(ValueError, match="arch"):
        ts.Simulation(scene, arch="tpu")
    with pytest.raises(ValueError, match="precision"):
        ts.Simulation(scene, arch=arch, precision="f16")
    with pytest.raises(ValueError, match="step_fraction"):
        ts.Simulation(scene, arch=arch, step_fraction=0)
    with pytest.raises(ValueError, match="max_sweeps"):
        ts.Simulation(scene, arch=arch, max_sweeps=0)
    tiny = ts.Scene.from_arrays([[0.5, 0.5, 0.5]], [[0, 0, 0]], 0.2, periodic=True)
    with pytest.raises(ValueError, match="periodic axis x"):
        ts.Simulation(tiny, arch=arch)
    # what f32 cannot hold is refused as taichi-spheres run refuses it
    far = ts.Scene.from_arrays([[2e4, 2e4, 2e4]], [[1.0, 0, 0]], 0.05,
                               box=((2e4 - 1, 2e4 - 1, 2e4 - 1), (2e4 + 1, 2e4 + 1, 2e4 + 1)))
    with pytest.raises(ValueError, match="radius of sphere 0 .* f32"):
        ts.Simulation(far, arch=arch, precision="f32")
    fast = ts.Scene.from_arrays([[0.5, 0.5, 0.5]], [[1e20, 0, 0]], 0.1)
    with pytest.raises(ValueError, match="speed of sphere 0 .* overflows f32"):
        ts.Simulation(fast, arch=arch, precision="f32")


def test_restore_refuses_a_checkpoint_of_another_scene(arch):
    scene = gas(10, packing=0.05, periodic=True)
    sim = ts.Simulation(scene, arch=arch)
    sim.advance(0.01)
    other = ts.Simulation(dataclasses.replace(scene, restitution=0.5), arch=arch)
    with pytest.raises(ValueError, match="different scene"):
        other.restore(sim.checkpoint())


@pytest.mark.parametrize("periodic", [False, True])
def test_set_state_refuses_what_no_state_can_hold(arch, periodic):
    """set_state names the sphere whose position, velocity or spin is not finite or
    whose centre lies outside the box, and changes nothing then."""
    x = np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5]])
    scene = ts.Scene.from_arrays(x, np.zeros((2, 3)), 0.1, periodic=(periodic,) * 3)
    sim = ts.Simulation(scene, arch=arch)
    v = np.zeros((2, 3))
    cases = [(dict(x=np.array([[0.3, 0.5, 0.5], [np.nan, 0.5, 0.5]])), "x of sphere 1"),
             (dict(v=np.array([[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]])), "v of sphere 1"),
             (dict(omega=np.array([[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]])), "omega of sphere 0"),
             (dict(x=np.array([[5.0, 0.5, 0.5], [0.7, 0.5, 0.5]])), "sphere 0: centre"),
             (dict(x=np.array([[0.3, 0.5, 1.0], [0.7, 0.5, 0.5]])), None),
             (dict(x=np.array([[0.3, 0.5, 1.0 + 1e-5], [0.7, 0.5, 0.5]])), "sphere 0: centre"),
             (dict(time=float("nan")), "time must be finite"),
             (dict(v=np.array([[1e200, 0.0, 0.0], [0.0, 0.0, 0.0]])), "speed of sphere 0"),
             (dict(omega=np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])), "no friction")]
    for change, words in cases:
        given = dict(x=x, v=v, omega=None, time=None) | change
        if words is None:   # on the wall, or on hi of a periodic axis (an f32 wrap's result)
            sim.set_state(**given)
            continue
        with pytest.raises(ValueError, match=words):
            sim.set_state(**given)
    sim.set_state(x, v, time=0.0)
    np.testing.assert_array_equal(sim.state().x, x)


def test_a_state_wrapped_onto_hi_in_f32_restores(arch):
    """In f32 the periodic wrap x + L of a centre a hair below lo rounds onto hi: such
    a state, made by the engine, restores from its checkpoint."""
    scene = ts.Scene.from_arrays([[0.5, 0.5, 0.5]], [[-1.0, 0.0, 0.0]], 0.1,
                                 periodic=(True,) * 3)
    on_hi = 0
    for k in range(1, 40):
        sim = ts.Simulation(scene, arch=arch, precision="f32")
        sim.advance_to(0.5 + k * 1e-9)
        if sim.state().x[0, 0] >= 1.0:
            on_hi += 1
            sim.restore(sim.checkpoint())
    assert on_hi > 0


def test_parallel_colour_launches_give_the_serial_bits(arch, monkeypatch):
    """The CPU resolves few pending pairs in one serial loop over the colours and many
    (above Performance.serial_resolve_pairs) with one parallel launch per colour, as a GPU
    always does. Forced onto the parallel launches, an inelastic walled gas under
    gravity gives the same bits: within a colour no two threads touch one sphere. So
    does a run whose re-detections visit the touched spheres in list order instead of
    cell order when few were touched (Performance.dense_touched = 64: more than 46 of the
    3,000 touched in cell order, fewer in list order: a step's first sweeps touch more,
    its last ones fewer)."""
    from taichi_spheres.config import DEFAULT
    scene = gas(3000, packing=0.3, periodic=(True, True, False), gravity=(0, 0, -9.81),
                restitution=0.8, wall_restitution=0.9, seed=4)
    runs = []
    tunings = {"serial": DEFAULT, "parallel": DEFAULT.with_(few_pairs=-1, serial_resolve_pairs=-1),
               "list order": DEFAULT.with_(dense_touched=64)}
    for force, tuning in tunings.items():
        sim = ts.Simulation(scene, arch=arch, tuning=tuning)
        launches = []
        per_colour = sim.debug_view().contacts.resolve_colour_parallel
        # (restored at the end: the engine's kernels serve later Simulations)
        monkeypatch.setattr(sim.debug_view().contacts, "resolve_colour_parallel",
                            lambda k, launch=per_colour: (launches.append(k), launch(k)))
        sim.advance(25 * sim.max_step())
        runs.append((sim.state(), sim.stats))
        assert bool(launches) == (force == "parallel" or arch != "cpu")
    (a, stats_a) = runs[0]
    assert stats_a["pair_collisions"] > 1000 and stats_a["wall_collisions"] > 0
    for b, stats_b in runs[1:]:
        assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
        # energy books are sums of float atomics: their order may differ in parallel
        assert_same_counters(stats_a, stats_b, sim, parallel_sums=True)


@pytest.mark.parametrize("kind", ["gas", "radii", "masses", "gravity"])
def test_memory_estimate_matches_the_fields(arch, precision, kind):
    """``cli info``'s estimate (no Taichi) stays within 3 % of the bytes the fields of a
    built Simulation take, for each feature that adds fields (near lists included:
    3,500 spheres)."""
    scene = gas(3500, packing=0.3, seed=3)
    rng = np.random.default_rng(0)
    radius, mass, kw = scene.radius, None, {}
    if kind == "radii":
        radius = scene.radius * rng.uniform(0.5, 1.0, scene.n)
    if kind == "masses":
        mass = rng.uniform(1.0, 2.0, scene.n)
    if kind == "gravity":
        kw = dict(gravity=(0, 0, -9.81), restitution=0.5, periodic=(True, True, False))
    scene = ts.Scene.from_arrays(scene.x, scene.v, radius, mass=mass,
                                 box=(scene.box_lo, scene.box_hi),
                                 **{"periodic": scene.periodic, **kw})
    sim = ts.Simulation(scene, arch=arch, precision=precision)
    actual = sim.field_bytes()
    real = 8 if precision == "f64" else 4
    engine = sim.debug_view().engine      # may be an earlier Simulation's, with room for more
    assert engine.capacity >= scene.n and engine.cell_capacity >= sim.geometry.n_cells
    assert ts.simulation._field_nbytes(sim.debug_view().state.x) == 3 * real * engine.capacity
    assert actual > 2 * 3 * real * engine.capacity
    estimate = ts.simulation.field_bytes_for(engine.capacity, engine.cell_capacity,
                                             sim.features, engine.key.near_lists, precision,
                                             cpu=arch == "cpu")
    assert abs(estimate / actual - 1) < 0.03, (kind, estimate, actual)
    fresh = (ts.engine.capacity_for(scene.n, ts.engine.MIN_SPHERES),
             ts.engine.capacity_for(sim.geometry.n_cells, ts.engine.MIN_CELLS))
    if (engine.capacity, engine.cell_capacity) == fresh and arch == "cpu":
        assert estimate == ts.simulation.estimate_field_bytes(scene, precision)
