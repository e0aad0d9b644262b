#!/usr/bin/env python3
"""A frictional pour settling into a bed: wall time per simulated second, rest and
overlaps, for several friction coefficients.

Loads scenes/pour.toml (2,000 spheres, e = 0.5, poured into a box; settled by ~1 s),
sets the pair and wall friction mu (and rolling friction mu_r), and runs it on one
thread over the phases "fall" [0, T1] and "bed" [T1, T2] (default 1 and 2 s), the
first step's compilation excluded. Reported per mu: wall seconds per simulated second
of each phase, velocity sweeps per step in the bed, kinetic energy (spin included) at
T2 over the initial energy, and the largest overlap left after a step in the bed
(relative to the contact distance).

    python tools/friction_bed.py                      # mu 0 and 0.5, ~5 min
    python tools/friction_bed.py --write              # the 'friction-bed' section of docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from machine import cpu_name, publish, untimed_pass  # noqa: E402


def phases(scene, t1, t2, threads) -> dict:
    """Wall s per simulated s of [0, t1] and [t1, t2], sweeps per step and overlap in the
    bed, and the kinetic energy at t2 / the initial energy."""
    sim = ts.Simulation(scene, threads=threads)
    untimed_pass(sim, lambda s: s.advance_to(t2))
    t0 = time.perf_counter()
    sim.advance_to(t1)
    fall = (time.perf_counter() - t0) / t1
    before = dict(sim.stats)
    worst = 0.0
    t0 = time.perf_counter()
    while sim.time < t2:
        sim.step_toward(t2)
        worst = max(worst, sim.last_step["max_overlap"])
    bed = (time.perf_counter() - t0) / (t2 - t1)
    s = sim.stats
    steps = s["steps"] - before["steps"]
    st = sim.state()
    ke = ts.observe.kinetic_energy(st) + ts.observe.rotational_energy(st)
    return dict(fall=fall, bed=bed, steps=steps,
                sweeps=(s["contact_iterations"] - before["contact_iterations"]) / steps,
                ke=ke / sim.initial_energy, overlap=worst)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=os.path.join(HERE, "..", "scenes", "pour.toml"))
    p.add_argument("--mu", type=float, nargs="+", default=[0.0, 0.5])
    p.add_argument("--mu-r", type=float, default=0.0)
    p.add_argument("--phases", type=float, nargs=2, default=(1.0, 2.0))
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--write", action="store_true")
    a = p.parse_args(argv)
    scene = ts.load_scene(a.scene)
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, {a.threads} thread(s): "
             f"`python tools/friction_bed.py {' '.join(x for x in argv if x != '--write')}`"
             .rstrip(), "",
             f"`{os.path.relpath(a.scene, os.path.join(HERE, '..'))}` with friction mu "
             f"(pairs and walls), rolling friction {a.mu_r:g}; fall [0, {a.phases[0]:g}] s, "
             f"bed [{a.phases[0]:g}, {a.phases[1]:g}] s.", "",
             "| mu | fall: wall s / sim s | bed: wall s / sim s | bed steps | sweeps / step "
             "| KE(end) / E0 | max overlap in the bed |", "|---|---|---|---|---|---|---|"]
    for mu in a.mu:
        r = phases(scene.replace(friction=mu, wall_friction=None, rolling_friction=a.mu_r),
                   a.phases[0], a.phases[1], a.threads)
        lines.append(f"| {mu:g} | {r['fall']:.2f} | {r['bed']:.2f} | {r['steps']} | "
                     f"{r['sweeps']:.1f} | {r['ke']:.1e} | {r['overlap']:.1e} |")
        print(lines[-1], flush=True)
    publish("\n".join(lines), "friction-bed", a.write)


if __name__ == "__main__":
    main()
