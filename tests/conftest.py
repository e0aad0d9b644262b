"""Test configuration: the arch comes from a fixture, never from import-time ti.init.

``--arch`` picks the backend (default cpu); ``--slow`` enables long validation runs;
TAICHI_SPHERES_FAILURE_LOG names a file that gets each failure's report at once;
``--compile`` how Taichi compiles (default fast: same bits, ~3x shorter compiles, which
are most of the suite's time; see taichi_spheres/runtime.py COMPILE_MODES).
Tests marked ``own_runtime`` initialise Taichi with settings of their own (thread
counts, precision, compile mode) and run between the f64 and the f32 tests: a test
that does so unmarked makes the tests after it in its worker compile their engines
again (docs/bench.md, "Test suite").
Tolerances depend on precision: ``tol`` scales a relative tolerance by the machine
epsilon of the precision under test.
"""
import os

import numpy as np
import pytest


def pytest_addoption(parser):
    parser.addoption("--arch", default="cpu", help="Taichi arch for the tests (cpu|cuda|vulkan|metal|gpu)")
    parser.addoption("--slow", action="store_true", default=False, help="run slow validation tests")
    parser.addoption("--compile", default=None, choices=["fast", "optimized"],
                     help="Taichi compile mode for the tests (taichi_spheres.runtime."
                          "COMPILE_MODES; default: TAICHI_SPHERES_COMPILE if set, else fast)")


def pytest_configure(config):
    # before any test initialises Taichi (every xdist worker runs this too)
    from taichi_spheres.runtime import COMPILE_ENV    # (imports taichi, no ti.init)
    mode = config.getoption("--compile")
    if mode:
        os.environ[COMPILE_ENV] = mode
    else:
        os.environ.setdefault(COMPILE_ENV, "fast")


#: a file each failure's report is appended to as soon as it happens (a run cut off by
#: a time limit, e.g. tools/cuda_checks.sh, keeps the failures pytest prints at its end)
FAILURE_LOG_ENV = "TAICHI_SPHERES_FAILURE_LOG"


def pytest_runtest_logreport(report):
    path = os.environ.get(FAILURE_LOG_ENV)
    if path and report.failed:
        with open(path, "a", encoding="utf-8") as out:
            out.write(f"==== {report.nodeid} ({report.when})\n{report.longreprtext}\n\n")


def _runs_f32(item) -> bool:
    callspec = getattr(item, "callspec", None)
    return callspec is not None and callspec.params.get("precision") == "f32"


def pytest_collection_modifyitems(config, items):
    # f64 tests first, then those that initialise Taichi their own way (own_runtime:
    # other thread counts, precision or compile mode), then f32: a process has one
    # Taichi runtime, so each switch re-initialises it and drops every compiled engine
    # (taichi_spheres/engine.py), and the tests after it would compile theirs again.
    # Between the two precisions the f32 tests re-initialise anyway, and a test that
    # asks for the f64 runtime's own thread count still finds its engines
    items.sort(key=lambda item: (_runs_f32(item),
                                 item.get_closest_marker("own_runtime") is not None))
    if config.getoption("--slow"):
        return
    skip = pytest.mark.skip(reason="slow validation run: use --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def arch(request):
    return request.config.getoption("--arch")


EPS = {"f64": float(np.finfo(np.float64).eps), "f32": float(np.finfo(np.float32).eps)}


@pytest.fixture(params=["f64", "f32"])
def precision(request, arch):
    if request.param == "f64" and arch in ("metal",):
        pytest.skip("no f64 on this arch")
    return request.param


def tol(precision, factor=1.0):
    """Relative tolerance: factor x machine epsilon of the precision."""
    return factor * EPS[precision]


def tol_for(sim, f64_value, f32_factor):
    """Tolerance for a test that runs its arch's default precision (f64 on the CPU and
    CUDA, f32 on Vulkan and Metal): f64_value in f64, f32_factor x f32's machine
    epsilon in f32."""
    return f64_value if sim.precision == "f64" else tol("f32", f32_factor)


def assert_same_counters(a: dict, b: dict, sim, parallel_sums: bool | None = None) -> None:
    """Two runs' ``stats`` are equal; where parallel threads summed the energy books and
    the virial (float atomics in thread order: on a GPU, and on the CPU's parallel
    paths, ``parallel_sums``; default: on GPUs), those only to round-off (README,
    "Same bits")."""
    if parallel_sums is None:
        parallel_sums = not sim.runtime.is_cpu
    for key, value in a.items():
        if not parallel_sums or not (key.startswith("energy") or key == "virial"):
            assert b[key] == value, key
        else:
            assert b[key] == pytest.approx(value, rel=tol_for(sim, 1e-12, 1e2)), key


def brute_overlap(st, scene):
    """Largest pair or box-wall overlap / contact distance of state ``st`` in
    ``scene``'s box (brute force over all pairs)."""
    d = np.linalg.norm(st.x[:, None] - st.x[None], axis=-1)
    s = st.radius[:, None] + st.radius[None]
    np.fill_diagonal(d, np.inf)
    worst = max(0.0, float(np.max((s - d) / s)))
    lo = st.x - st.radius[:, None] - scene.box_lo
    hi = scene.box_hi - st.x - st.radius[:, None]
    return max(worst, float(-min(lo.min(), hi.min()) / (2 * st.radius.min())))


def walled_gravity_gas():
    """30 spheres of unequal masses (0.5-2 kg, radius 0.05 m) moving at 3 m/s in a
    walled box under gravity (e = 0.7, wall e = 0.8), none resting in the first 0.5 s:
    the scene the engine must follow the event-driven reference on (test_reference,
    test_substeps)."""
    from taichi_spheres.builders import gas
    from taichi_spheres.scene import Scene
    rng = np.random.default_rng(7)
    base = gas(30, packing=0.05, radius=0.05, periodic=False, speed=3.0, seed=7)
    return Scene.from_arrays(base.x, base.v, base.radius, mass=rng.uniform(0.5, 2.0, 30),
                             box=(base.box_lo, base.box_hi), gravity=(0, 0, -9.81),
                             restitution=0.7, wall_restitution=0.8)
