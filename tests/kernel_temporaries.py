"""Print the Taichi IR of every kernel a frictional silo scene compiles (child process).

Run as ``python tests/kernel_temporaries.py [no-substeps]``: the scene has gravity, two
materials with unequal radii (shock propagation, per-sphere inertia), rolling and
twisting resistance, a floor with an orifice, a cylinder, a cone and a sink, and every
loop runs in parallel, the contact solver's sweeps in batches of two per wait (as on
a GPU: Performance.gpu_sweeps_per_wait) with their caps scaled to the step
(Rules.step_scaled_sweeps); it runs with the bounded position pass as well. With
``no-substeps`` it runs without substeps (then the overlap measure over every pair
runs), with one sweep per wait and full caps (the per-sweep kernels).
Taichi writes the IR to this process's stdout, which tests/test_kernel_temporaries.py
reads. Not covered: the fused step and the serial solver (CPU-only paths, one task
each) and the `optimized` compile mode (the test compiles `fast`; the temporaries
come from Taichi's offload pass, which runs in both).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import runtime  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402


def scene():
    """A small silo holding every feature a frictional scene compiles."""
    rng = np.random.default_rng(1)
    xy = 0.1 + 0.025 * np.arange(4)
    x = np.array([(a, b, 0.15 + 0.03 * k) for a in xy for b in xy for k in range(2)])
    x += rng.uniform(-1e-3, 1e-3, x.shape)
    radius = np.where(np.arange(len(x)) % 2 == 0, 0.008, 0.01)
    return ts.Scene.from_arrays(
        x, np.zeros_like(x), radius, density=2500.0, box=((0, 0, 0), (0.3, 0.3, 0.4)),
        restitution=0.5, wall_restitution=0.5, friction=0.4, rolling_friction=0.05,
        tangential_restitution=0.3,
        materials=[ts.Material("glass", restitution=0.97, friction=0.092),
                   ts.Material("rubber", restitution=0.6, friction=0.8,
                               rolling_friction=0.05)],
        material=np.arange(len(x)) % 2,
        geometry=[ts.Plane((0.15, 0.15, 0.05), (0, 0, 1), hole=0.02),
                  ts.Cylinder((0.15, 0.15, 0.05), (0, 0, 1), 0.12, length=0.3),
                  ts.Cone((0.15, 0.15, 0.3), (0, 0, 1), 0.12, 0.14, 0.05)],
        sinks=[ts.Sink((0, 0, 0), (0.3, 0.3, 0.02))])


def main():
    for mode in runtime.COMPILE_MODES.values():
        mode["print_ir"] = True
        mode["print_ir_dbg_info"] = False
    tuning = Tuning().with_(serial_solver_below=0, serial_light_below=0,
                            serial_heavy_below=0, bounded_position_pass=True,
                            sweeps_per_wait=2,   # the batched sweeps of a GPU
                            step_scaled_sweeps=True)
    if sys.argv[1:] == ["no-substeps"]:
        tuning = tuning.with_(substeps=False, sweeps_per_wait=1, step_scaled_sweeps=False)
    sim = ts.Simulation(scene(), threads=2, tuning=tuning, compile_all=True)
    sim.advance(0.02)


if __name__ == "__main__":
    main()
