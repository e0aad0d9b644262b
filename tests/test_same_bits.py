"""Same bits on every CPU: stored digests of the reference scenes.

``builders.same_bits_scene`` (inelastic pairs and walls, gravity, periodic sides,
floor and ceiling, unequal radii and masses) is run for a fixed time and the bits of
its final positions and velocities are hashed (``observe.state_digest``). The digests
in ``tests/same_bits.json`` were computed by ``python tools/state_digest.py --write``;
every CPU (any x86-64 model, with or without AVX-512 and FMA; ARM), both compile
modes, the fused step and the per-colour parallel launches must reproduce them (the
"plain" case: the small one with plain sweeps at 100 / 100, the full caps in every
step and no substeps; the "equal" case: the small one with equal radii and masses). A
change of the physics changes them on purpose: store the new ones with that command
and say why in the commit.

What makes this hold is ``runtime.FAST_MATH = False``: with Taichi's default fast
math, LLVM fuses multiply-adds where the CPU has FMA and as its cost model picks per
kernel, so the "small" case gave another digest in each compile mode on an AVX-512
CPU (f64: 8635d2a254a2d6bc fast, 47a4b6901caf68e8 optimized, against the stored
8cc27c0e86a30ba3).
"""
import json
import os

import pytest

import taichi_spheres as ts
from taichi_spheres import runtime
from taichi_spheres.builders import same_bits_case_scene, same_bits_scene
from taichi_spheres.config import DEFAULT

with open(os.path.join(os.path.dirname(__file__), "same_bits.json")) as _f:
    STORED = json.load(_f)


def _digest(case, precision, arch="cpu", **kw):
    """(digest, Simulation) of the reference scene of ``case`` after its run."""
    stored = STORED[case]
    scene = same_bits_case_scene(stored)
    kw["tuning"] = kw.get("tuning", DEFAULT).with_(**stored.get("tuning", {}))
    sim = ts.Simulation(scene, arch=arch, precision=precision, **kw)
    sim.advance(STORED[case]["duration"])
    return ts.observe.state_digest(sim.state(), precision), sim


def _cpu_only(arch):
    if arch != "cpu":
        pytest.skip("the stored digests are the CPU's (GPUs: tests/test_gas.py compares "
                    "their runs with each other)")


@pytest.mark.parametrize("case", ["small", "large", "frictional", "materials", "plain",
                                  "equal"])
def test_reference_scenes_give_the_stored_digests(arch, precision, case):
    _cpu_only(arch)
    digest, sim = _digest(case, precision)
    assert sim.stats["pair_collisions"] > 1000 and sim.stats["wall_collisions"] > 100
    if case == "equal":     # the equal-mass row updates and packed rows ran
        solver = sim.debug_view().solver
        assert sim.stats["contacts"] > 0 and solver.halved_residual and solver.packed
    assert digest == STORED[case]["digests"][precision]


@pytest.mark.parametrize("case", ["small", "frictional", "materials", "plain"])
def test_fused_step_gives_the_stored_digest(arch, case):
    _cpu_only(arch)
    digest, sim = _digest(case, "f64", fused=True)
    assert sim.fused
    assert digest == STORED[case]["digests"]["f64"]


def test_parallel_colour_launches_give_the_stored_digest(arch, monkeypatch):
    """From 3,000 spheres on, the CPU may launch a sweep per colour in parallel (as a GPU
    always does); forced onto those launches, the large case keeps its digest."""
    _cpu_only(arch)
    digest, sim = _digest("large", "f64",
                          tuning=DEFAULT.with_(few_pairs=-1, serial_resolve_pairs=-1))
    launches = []
    per_colour = sim.debug_view().contacts.resolve_colour_parallel
    # (restored at the end: the engine's kernels serve later Simulations)
    monkeypatch.setattr(sim.debug_view().contacts, "resolve_colour_parallel",
                        lambda k, launch=per_colour: (launches.append(k), launch(k)))
    sim.advance(sim.max_step())
    assert launches, "the sweeps did not launch per colour"
    assert digest == STORED["large"]["digests"]["f64"]


def test_fast_math_stays_off():
    """Taichi's fast math makes the bits depend on the CPU model and compile mode."""
    assert runtime.FAST_MATH is False


def test_thread_local_copies_only_on_the_cpu():
    """On a GPU, thread-local copies of the step's counters make every launched thread
    (a device-filling number for loops with bounds read from fields) fold its copy into
    the counter: ms per kernel (runtime.GPU_THREAD_LOCAL). The CPU keeps Taichi's
    default, with which the stored digests were made."""
    import taichi as ti
    cpu = runtime.init_options("cpu", "f64", "fast", 2)
    assert cpu == dict(arch=ti.cpu, default_fp=ti.f64, default_ip=ti.i32, offline_cache=True,
                       log_level=ti.WARN, random_seed=0, fast_math=False,
                       advanced_optimization=False, cpu_max_num_threads=2)
    for gpu in ("cuda", "gpu", "vulkan"):
        opts = runtime.init_options(gpu, "f32", "optimized", None)
        assert opts["make_thread_local"] is False and opts["fast_math"] is False
        assert "cpu_max_num_threads" not in opts


def test_simulations_share_an_engine_and_keep_their_bits(arch, precision):
    """A later Simulation with the same compiled features and no more spheres runs on
    the earlier one's engine (compiles nothing: tools/compile_once.py), also when both
    stay alive: stepping two of them in turn gives each the bits it gets alone."""
    big = same_bits_scene(300)
    small = same_bits_scene(200)
    alone = ts.Simulation(big, arch=arch, precision=precision)
    for _ in range(4):
        alone.advance(0.05)
    a = ts.Simulation(big, arch=arch, precision=precision)
    b = ts.Simulation(small, arch=arch, precision=precision)
    assert a._engine is alone._engine and b._engine is a._engine
    b_alone = ts.Simulation(small, arch=arch, precision=precision)
    for _ in range(4):
        b_alone.advance(0.05)
    for _ in range(4):
        a.advance(0.05)
        b.advance(0.05)
    for sim, ref in ((a, alone), (b, b_alone)):
        assert ts.observe.state_digest(sim.state(), precision) == \
            ts.observe.state_digest(ref.state(), precision)
        assert sim.stats["pair_collisions"] == ref.stats["pair_collisions"] > 100
