"""Sinks taking spheres out in place (Performance.discharge_in_place): in the engine's
fields (takeout.py, Engine.take_out), or with a recycling sink on the host with the
remaining spheres' warm-start table moved down in the fields (Engine.keep_spheres,
contacts/warm_table.py); the same bits as reading every table to the host,
renumbering it (discharge.renumber_warm) and loading the scene again.
"""
import dataclasses

import numpy as np
import pytest

import taichi_spheres as ts
from taichi_spheres.config import HOST_ONLY, KERNEL_VARIANTS, Tuning
from taichi_spheres.discharge import DROPPED_PARTNER, renumber_warm

GLASS = ts.Material("glass", restitution=0.5, friction=0.3)
RUBBER = ts.Material("rubber", restitution=0.4, friction=0.6, rolling_friction=0.02)


def _silo(recycle=False, materials=False, substeps=True):
    """~60 spheres (radii 4.5-5 mm) in a cylinder on a plane with an orifice of 20 mm,
    a sink below; friction 0.5, or two materials (one with rolling friction)."""
    rng = np.random.default_rng(3)
    g = (np.arange(5) - 2) * 0.013
    x = np.array([(0.06 + a, 0.06 + b, 0.06 + 0.012 * k) for a in g for b in g
                  for k in range(4)], float)
    x = x[np.hypot(x[:, 0] - 0.06, x[:, 1] - 0.06) < 0.04]
    radius = rng.uniform(0.0045, 0.005, len(x))
    extra = (dict(materials=[GLASS, RUBBER], material=np.arange(len(x)) % 2) if materials
             else dict(friction=0.5))
    scene = ts.Scene.from_arrays(
        x, np.zeros_like(x), radius, box=((0, 0, 0), (0.12, 0.12, 0.2)), restitution=0.5,
        wall_restitution=0.5,
        geometry=[ts.Plane((0.06, 0.06, 0.05), (0, 0, 1), hole=0.02),
                  ts.Cylinder((0.06, 0.06, 0.05), (0, 0, 1), 0.05, length=0.15)],
        sinks=[ts.Sink((0, 0, 0), (0.12, 0.12, 0.03), recycle=recycle)], **extra)
    return scene, Tuning().with_(substeps=substeps)


def _warm_in_use(warm: dict) -> dict:
    """The warm-start table's bytes in the slots in use (the others hold whatever the
    engine's fields held before)."""
    slots = warm["key"].shape[1]
    used = np.arange(slots)[None, :] < np.minimum(warm["kept"], slots)[:, None]
    return {k: (w[used] if k in ("key", "lam", "warm_t", "warm_r") else np.asarray(w)).tobytes()
            for k, w in warm.items()}


def _run(scene, tuning, arch, precision, in_place, times):
    """(x, v, omega bytes, warm table, stats, sphere ids) after each of ``times`` [s]."""
    sim = ts.Simulation(scene, arch=arch, precision=precision,
                        tuning=tuning.with_(discharge_in_place=in_place))
    out = []
    for t in times:
        sim.advance_to(t)
        st = sim.state()
        out.append((st.x.tobytes(), st.v.tobytes(), st.omega.tobytes(),
                     _warm_in_use(sim.debug_view().solver.warm_rows(sim.n)),
                     {k: sim.stats[k] for k in ("steps", "discharged", "contact_iterations",
                                                "energy_discharged", "contacts")},
                     sim.sphere_ids.tolist()))
    take_out = sim.debug_view().engine._take_out
    if in_place and take_out is not None:  # the schedule's: serial, or through the scratch
        assert (take_out.scratch is None) == sim.schedule.serial_light
    return out, sim.stats["discharged"]


def _same_bits_both_ways(arch, precision, case):
    scene, tuning = _silo(**case)
    times = (0.25, 0.4)
    in_place, gone = _run(scene, tuning, arch, precision, True, times)
    reload, _ = _run(scene, tuning, arch, precision, False, times)
    assert gone > 0
    assert in_place == reload


@pytest.mark.parametrize("case", [
    dict(materials=True), pytest.param(dict(recycle=True), marks=pytest.mark.slow),
    pytest.param(dict(substeps=False), marks=pytest.mark.slow)])
def test_discharge_in_place_keeps_the_bits_of_a_reload(arch, case):
    """A discharging silo (polydisperse, frictional; with two materials, one with
    rolling friction; a recycling sink; or without substeps) gives the same positions,
    velocities, spins, warm-start tables and counters whether the discharge moves the
    warm start in place or through the host (f64)."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    _same_bits_both_ways(arch, "f64", case)


def _stacked_columns():
    """8 x 8 columns of 12 touching spheres (r = 5 mm, two materials, one with rolling
    friction) falling 0.1 r onto the floor, a sink over the floor's half x > 4.4 cm:
    768 spheres, three of takeout.CHUNK; the bottom sphere of each column there (32,
    indices 384 to 756, in the second and third chunks) enters it after ~7 ms, the
    spheres above keep their rows to it and to each other."""
    r, nx, nz = 0.005, 8, 12
    g = (np.arange(nx) + 0.5) * 2.2 * r
    X, Y, Z = np.meshgrid(g, g, 1.1 * r + 2 * r * np.arange(nz), indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    side = nx * 2.2 * r
    return ts.Scene.from_arrays(
        x, np.zeros_like(x), np.full(len(x), r), box=((0, 0, 0), (side, side, 0.15)),
        restitution=0.5, wall_restitution=0.5, materials=[GLASS, RUBBER],
        material=np.arange(len(x)) % 2,
        sinks=[ts.Sink((side / 2, 0, 0), (side, side, 1.05 * r))])


def test_take_out_in_parallel_keeps_the_bits_of_a_reload(arch):
    """Where the light loops run in parallel (a GPU; here serial_light_below = 0) the
    take-out numbers the spheres that stay in chunks and moves them through a scratch
    copy: stacked columns whose bottom spheres in one half enter a sink (the first one
    taken in the second chunk, spheres before it that stay, partners that leave) give
    the same positions, velocities, spins, warm-start tables and counters as the
    reload through the host (f64)."""
    from taichi_spheres.takeout import CHUNK
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene = _stacked_columns()
    assert scene.n == 3 * CHUNK
    tuning = Tuning().with_(serial_light_below=0)
    times = (0.01, 0.03)
    in_place, gone = _run(scene, tuning, arch, "f64", True, times)
    reload, _ = _run(scene, tuning, arch, "f64", False, times)
    assert gone == 32
    assert in_place[0][-1][CHUNK:CHUNK + 128] == list(range(CHUNK, CHUNK + 128))
    assert in_place == reload


@pytest.mark.own_runtime
def test_discharge_in_place_keeps_the_bits_of_a_reload_in_f32(arch):
    """The same in f32, where the host's copies pass through float64."""
    _same_bits_both_ways(arch, "f32", {})


def test_host_only_options_share_the_compiled_engine(arch):
    """The options only the host reads (config.HOST_ONLY: the schedule's sphere counts,
    the impact sweep's and the contact solve's paths, sweeps per wait,
    discharge_in_place) and those that choose a variant of the solver's kernels
    (config.KERNEL_VARIANTS: the interleaving, the staged solve) are left out of the
    engines' key: Simulations that differ only in them run on one engine, and the
    engine's parts read each one's own options while it is bound (Engine.bind), the
    solver launching the kernel variant of its interleaving and staging."""
    scene, tuning = _silo()
    host = dict(discharge_in_place=False, few_pairs=7, serial_resolve_pairs=9,
                serial_solver_below=5, sweeps_per_wait=3, gpu_sweeps_per_wait=5,
                near_lists_from=scene.n + 1, serial_light_below=scene.n + 1,
                serial_heavy_below=scene.n + 1, solver_interleave=3,
                frictional_interleave=2, parallel_interleave=5, staged_solve=True)
    assert set(host) == set(HOST_ONLY + KERNEL_VARIANTS)
    assert Tuning().with_(**host).compiled() == Tuning().compiled() == Tuning()
    one = ts.Simulation(scene, arch=arch, precision="f64", tuning=tuning)
    other = ts.Simulation(scene, arch=arch, precision="f64", tuning=tuning.with_(**host))
    engine = one.debug_view().engine
    assert other.debug_view().engine is engine
    assert other.tuning.performance.discharge_in_place is False
    for sim in (other, one, other):
        sim.advance(1e-3)
        perf = sim.tuning.performance
        assert engine.contacts.host is perf
        assert engine.solver.serial_solver_below == perf.serial_solver_below
        assert engine.solver.batch == (perf.sweeps_per_wait if sim.runtime.is_cpu
                                       else perf.gpu_sweeps_per_wait)
        assert engine.solver.interleave == (perf.frictional_interleave if sim.runtime.is_cpu
                                            else 1)
    if one.runtime.is_cpu:     # a serial solve per interleaving and staging (serial engines)
        assert set(engine.solver._serial_solves) == {
            (2, True), (Tuning().performance.frictional_interleave, False)}


def _random_warm_table(solver, n: int, rng) -> dict:
    """A warm-start table of n spheres with random impulses and flags, partners among
    them, walls (< 0) and DROPPED_PARTNER, and counts up to warm_slots + 2 (more than
    the slots: every slot in use)."""
    table = solver.warm_rows(n)
    slots = table["key"].shape[1]
    out = dict(h_prev=1e-3)
    out["key"] = rng.integers(-9, n, size=(n, slots)).astype(table["key"].dtype)
    out["key"][0, 0] = DROPPED_PARTNER
    out["kept"] = rng.integers(0, slots + 3, size=n).astype(table["kept"].dtype)
    for name in ("loaded", "near"):
        out[name] = rng.integers(0, 2, size=n).astype(table[name].dtype)
    for name in ("lam", "warm_t", "warm_r"):
        out[name] = rng.random(table[name].shape).astype(table[name].dtype)
    return out


def test_warm_table_moves_down_as_the_host_renumbers_it(arch):
    """ContactSolver.keep_spheres on a random table (rolling friction: every impulse
    table) leaves, in the slots in use, what discharge.renumber_warm makes of it."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene, tuning = _silo(materials=True)
    sim = ts.Simulation(scene, arch=arch, precision="f64", tuning=tuning)
    solver = sim.debug_view().solver
    rng = np.random.default_rng(7)
    table = _random_warm_table(solver, sim.n, rng)
    solver.load_warm(table)
    keep = rng.random(sim.n) < 0.6
    keep[0] = True
    smaller = dataclasses.replace(scene, x=scene.x[keep], v=scene.v[keep],
                                  radius=scene.radius[keep], mass=scene.mass[keep],
                                  omega=scene.omega[keep], material=scene.material[keep])
    solver.keep_spheres(smaller, sim.geometry, None, keep)
    got = solver.warm_rows(int(keep.sum()))
    expected = renumber_warm(table, keep)
    assert DROPPED_PARTNER in expected["key"]
    expected = {k: np.asarray(w, dtype=np.asarray(got[k]).dtype) for k, w in expected.items()}
    assert _warm_in_use(got) == _warm_in_use(expected)


def test_discharge_in_place_beside_another_simulation(arch):
    """A Simulation that discharged in place, parked while another one of the same
    scene ran on its engine, goes on with the bits of one that ran alone."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene, tuning = _silo()
    alone, _ = _run(scene, tuning, arch, "f64", True, (0.25, 0.4))
    sim = ts.Simulation(scene, arch=arch, precision="f64", tuning=tuning)
    sim.advance_to(0.25)
    assert sim.stats["discharged"] > 0
    other = ts.Simulation(scene, arch=arch, precision="f64", tuning=tuning)
    other.advance(0.05)
    assert other.debug_view().engine is sim.debug_view().engine
    sim.advance_to(0.4)
    st = sim.state()
    assert (st.x.tobytes(), st.v.tobytes(), st.omega.tobytes()) == alone[1][:3]


def test_renumbered_warm_table_drops_the_partners_that_left():
    """The host's renumbering (which the in-place move reproduces): rows in use keep
    their partner's new index, or DROPPED_PARTNER where it left; walls (< 0) and the
    unused slots stay."""
    key = np.array([[1, 2, -3, 7], [2, -1, 0, 0], [0, 0, 0, 0]], dtype=np.int32)
    warm = dict(key=key, lam=np.ones((3, 4)), kept=np.array([3, 2, 0]),
                loaded=np.array([1, 1, 0]), h_prev=1e-3)
    out = renumber_warm(warm, np.array([True, False, True]))
    assert out["key"].tolist() == [[DROPPED_PARTNER, 1, -3, 7], [0, 0, 0, 0]]
    assert out["kept"].tolist() == [3, 0]


def _gas_into_a_sink(n=40, seed=5, lead=False):
    """n elastic spheres (radii 4-5 mm) without gravity, drifting towards +x with
    random velocities into a sink at the far end: no contact solver. ``lead``: sphere 0
    is the largest (6 mm) and runs ahead, into the sink ~0.2 s before the others."""
    rng = np.random.default_rng(seed)
    g = np.arange(n)
    x = np.stack([0.02 + 0.012 * (g % 4), 0.02 + 0.012 * ((g // 4) % 5),
                  0.02 + 0.012 * (g // 20)], axis=1).astype(float)
    v = rng.normal(0.0, 0.05, (n, 3)) + np.array([0.4, 0.0, 0.0])
    radius = rng.uniform(0.004, 0.005, n)
    if lead:
        x[0], v[0], radius[0] = (0.125, 0.05, 0.03), (0.6, 0.0, 0.0), 0.006
    scene = ts.Scene.from_arrays(x, v, radius, box=((0, 0, 0), (0.2, 0.1, 0.06)),
                                 gravity=(0, 0, 0), restitution=1.0, wall_restitution=1.0,
                                 sinks=[ts.Sink((0.15, 0, 0), (0.2, 0.1, 0.06))])
    return scene


def test_take_out_in_place_without_a_contact_solver(arch):
    """A gas without a contact solver discharging into a sink: the take-out in the
    fields (takeout.py) gives the bits, counters and sphere ids of the host's reload."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene = _gas_into_a_sink()
    out = []
    for in_place in (True, False):
        sim = ts.Simulation(scene, arch=arch, precision="f64",
                            tuning=Tuning().with_(discharge_in_place=in_place))
        assert sim.debug_view().solver is None
        sim.advance_to(0.25)
        st = sim.state()
        out.append((st.x.tobytes(), st.v.tobytes(), sim.sphere_ids.tolist(),
                    {k: sim.stats[k] for k in ("steps", "discharged", "discharged_mass",
                                               "energy_discharged")}))
    assert 0 < out[0][3]["discharged"] < scene.n
    assert out[0] == out[1]


def test_every_sphere_leaves_in_place(arch):
    """When the sinks take every sphere out, the Simulation goes on empty: time runs,
    the state has no rows, the totals count every sphere and its mass, as with the
    host's reload."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene = _gas_into_a_sink(n=8)
    totals = []
    for in_place in (True, False):
        sim = ts.Simulation(scene, arch=arch, precision="f64",
                            tuning=Tuning().with_(discharge_in_place=in_place))
        sim.advance_to(0.6)
        assert sim.n == 0 and sim.state().x.shape == (0, 3)
        sim.advance(0.05)
        assert sim.time == pytest.approx(0.65)
        assert sim.stats["discharged"] == scene.n
        assert sim.stats["discharged_mass"] == pytest.approx(scene.mass.sum(), rel=1e-12)
        totals.append({k: sim.stats[k] for k in ("steps", "discharged_mass",
                                                 "energy_discharged")})
    assert totals[0] == totals[1]


def _scalars(sim) -> dict:
    """The scalars an engine loads from the bound scene (state, contacts)."""
    e = sim.debug_view().engine
    names = {"state": ("r0", "m0", "inv_m0", "inv_i0"), "contacts": ("half_m0", "walk_reach")}
    out = {f"{part}.{name}": getattr(getattr(e, part), name)[None]
           for part, fields in names.items() for name in fields}
    out["contacts.near_reach"] = e.contacts.near_reach
    return out


def test_take_out_loads_the_scalars_of_the_spheres_that_stay(arch):
    """When the first and largest sphere leaves, the take-out in the fields loads the
    scalars that follow from the first sphere's radius and mass and from the largest
    radius as the host's reload does (both runs share one engine: read in turn)."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene = _gas_into_a_sink(lead=True)
    seen = []
    for in_place in (True, False):
        sim = ts.Simulation(scene, arch=arch, precision="f64",
                            tuning=Tuning().with_(discharge_in_place=in_place))
        before = _scalars(sim)
        sim.advance_to(0.1)
        assert sim.stats["discharged"] == 1 and sim.sphere_ids[0] == 1
        after = _scalars(sim)
        assert after["state.r0"] != before["state.r0"]
        assert after["contacts.walk_reach"] < before["contacts.walk_reach"]
        seen.append(after)
    assert seen[0] == seen[1]


def test_an_emptied_simulation_restores_from_its_checkpoint(arch):
    """A Simulation every sphere of which has left through the sinks checkpoints and
    restores (into a new Simulation of the same scene), and goes on empty."""
    if arch == "metal":
        pytest.skip("no f64 on this arch")
    scene = _gas_into_a_sink(n=8)
    sim = ts.Simulation(scene, arch=arch, precision="f64")
    sim.advance_to(0.6)
    assert sim.n == 0
    ckpt = sim.checkpoint()
    other = ts.Simulation(scene, arch=arch, precision="f64")
    other.restore(ckpt)
    assert other.n == 0 and other.time == sim.time
    assert other.stats["discharged"] == scene.n
    other.advance(0.05)
    assert other.state().x.shape == (0, 3)
