"""tools/bench.py measures what it claims: its stage-by-stage step is Simulation.step,
its one-flag feature builds change the code and fields but not the results, and its
memory figures are counted right. No timings are asserted."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))

import bench  # noqa: E402  (tools/bench.py)
from taichi_spheres import Simulation  # noqa: E402
from taichi_spheres.simulation import _field_nbytes  # noqa: E402
from taichi_spheres.builders import gas  # noqa: E402


def _gas():
    return gas(216, packing=0.3, periodic=True, seed=3)


def test_staged_step_is_the_step(arch, precision):
    """The staged pass runs the same kernels in the same loop: same end state and sweeps."""
    sim = Simulation(_gas(), arch=arch, precision=precision)
    for _ in range(3):
        h = sim.max_step()
        start = sim.checkpoint()
        times = dict.fromkeys(bench.STAGES, 0.0)
        sweeps = bench.staged_step(sim, h, times)
        staged = sim.state()
        sim.restore(start)
        sim.step(h)
        assert np.array_equal(staged.x, sim.state().x)
        assert np.array_equal(staged.v, sim.state().v)
        assert sweeps == sim.last_step["sweeps"]
        assert all(t >= 0.0 for t in times.values())


def _field_layout(sim) -> set:
    """(part, field name, bytes per element) of the Taichi fields a Simulation runs on."""
    import taichi as ti
    from taichi_spheres.engine import field_parts
    out = set()
    for part in field_parts(sim.debug_view().engine):
        for name, value in vars(part).items():
            if isinstance(value, ti.Field):
                out.add((type(part).__name__, name, _field_nbytes(value) //
                         max(1, int(np.prod(value.shape)))))
    return out


def test_one_feature_compiled_in_changes_nothing_but_code(arch):
    """Each single-flag build gives the states of the default build; a per-sphere radius
    field costs exactly one real per sphere."""
    scene = _gas()
    base = Simulation(scene, arch=arch, precision="f64")
    for _ in range(4):
        base.step(base.max_step())
    for key, _label, flip in bench.FEATURE_FLIPS:
        sim = bench.simulation_with(scene, arch, "f64", flip)
        for _ in range(4):
            sim.step(sim.max_step())
        assert np.array_equal(sim.state().x, base.state().x), key
        # the fields differ only by the radius field, one real per sphere of the engine
        extra = _field_layout(sim) - _field_layout(base)
        assert extra == ({("SphereState", "radius", 8)} if key == "radii" else set()), key
        assert _field_layout(base) <= _field_layout(sim)
        if key == "radii":
            assert _field_nbytes(sim.debug_view().state.radius) == 8 * sim.debug_view().engine.capacity


def test_rss_and_exponent():
    """RSS is a positive byte count where /proc exists; a linear cost fits exponent 1."""
    if os.path.exists("/proc/self/statm"):
        assert bench.rss_bytes() > 0
    ns = [1e3, 1e4, 1e5]
    assert bench.fit_exponent(ns, [2.0 * n for n in ns]) == pytest.approx(1.0)


def test_steal_share():
    """Stolen CPU share from two /proc/stat readings; None when a reading is missing or
    no time passed."""
    assert bench.steal_share((10, 1000), (15, 1100)) == pytest.approx(0.05)
    assert bench.steal_share(None, (15, 1100)) is None
    assert bench.steal_share((10, 1000), (10, 1000)) is None
    now = bench.cpu_jiffies()
    if os.path.exists("/proc/stat"):
        assert now is not None and 0 <= now[0] <= now[1]
