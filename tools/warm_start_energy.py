#!/usr/bin/env python3
"""Energy after a heavy impact with and without the bounded warm start
(contacts/warm_energy.py, Rules.bounded_warm_start), without and with friction.

A ball ``ratio`` times heavier than the spheres of a settled FCC block of 256 spheres
(r = 0.01 m, e = 0.5, 1 s of settling) is dropped onto it at 1 m/s down and 0.3 m/s
sideways, its centre 0.05 m above the top sphere's and 3 mm off the block's axis (so
that friction acts), in a new Simulation at the default sweeps. For each mass ratio,
friction coefficient (pairs and walls) and warm-start mode: the largest growth of the
total energy (kinetic, spin included, and potential) in one of the next 300 steps, as
a fraction of the ball's kinetic energy when it reaches the block, and the steps whose
warm start the bound scaled (stats["warm_starts_scaled"]).

    python tools/warm_start_energy.py --write        # ~5 min on 1 core
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.builders import ball_on_block, fcc_block  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish, step_fraction_option  # noqa: E402  (tools/machine.py)

G = 9.81
R = 0.01
HEIGHT, DOWN, SIDE, OFF_AXIS = 0.05, 1.0, 0.3, 0.003


def settled_block(mu: float, tuning=None, step_fraction=None):
    """The 256-sphere block with friction mu, and its state after 1 s (``tuning``:
    default Tuning(); ``step_fraction``: the Simulation's, None for its default)."""
    block = fcc_block((4, 4, 4), radius=R, restitution=0.5).replace(
        friction=mu, wall_friction=mu)
    sim = ts.Simulation(block, threads=1, tuning=tuning or Tuning(),
                        **step_fraction_option(step_fraction))
    sim.advance(1.0)
    return block, sim.state()


def drop(block, settled, ratio: float, mode: str, steps: int, tuning=None,
         step_fraction=None) -> dict:
    """The ball dropped onto the settled block (module docstring) under
    bounded_warm_start ``mode`` (other settings: ``tuning``, default Tuning();
    ``step_fraction``: the Simulation's, None for its default): largest
    one-step energy growth / impact energy, the step it happened, steps scaled."""
    scene, x, v = ball_on_block(block, settled, ratio, HEIGHT, DOWN, offset=OFF_AXIS,
                                side=SIDE)
    mass = scene.mass
    sim = ts.Simulation(scene, threads=1,
                        tuning=(tuning or Tuning()).with_(bounded_warm_start=mode),
                        **step_fraction_option(step_fraction))
    sim.set_state(x, v)
    energy = [sim.energy_budget()["current"]]
    for _ in range(steps):
        sim.advance(sim.max_step())
        energy.append(sim.energy_budget()["current"])
    growth = np.diff(energy)
    impact = 0.5 * mass[-1] * (DOWN ** 2 + SIDE ** 2 + 2 * G * (HEIGHT - 2 * R))
    return dict(growth=max(float(growth.max()), 0.0) / impact, step=int(np.argmax(growth)) + 1,
                scaled=int(sim.stats["warm_starts_scaled"]), impacts=int(sim.stats["pair_collisions"]))


def report(rows: dict, steps: int) -> str:
    """The markdown section."""
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: "
             "`python tools/warm_start_energy.py --write`.", "",
             "A ball `ratio` x heavier dropped (1 m/s down, 0.3 m/s sideways) onto a settled "
             f"FCC block of 256 spheres, default sweeps; the largest growth of the total energy "
             f"in one of the next {steps} steps, / the ball's kinetic energy at impact, and the "
             "steps whose warm start the bound scaled:", "",
             "| mass ratio | friction | bounded_warm_start | largest one-step growth / impact "
             "energy | at step | steps scaled |", "|---|---|---|---|---|---|"]
    for (ratio, mu, mode), r in rows.items():
        lines.append(f"| {ratio:g} | {mu:g} | {mode} | {r['growth']:.1e} | {r['step']} | "
                     f"{r['scaled']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ratios", type=float, nargs="+", default=[8.0, 30.0, 100.0])
    ap.add_argument("--frictions", type=float, nargs="+", default=[0.0, 0.5])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    args = ap.parse_args(argv)
    if min(args.ratios) <= 0 or min(args.frictions) < 0 or args.steps < 1:
        ap.error("ratios must be > 0, frictions >= 0, steps >= 1")
    rows = {}
    for mu in args.frictions:
        block, settled = settled_block(mu)
        for ratio in args.ratios:
            for mode in ("off", "on"):
                rows[ratio, mu, mode] = drop(block, settled, ratio, mode, args.steps)
                print(ratio, mu, mode, rows[ratio, mu, mode], flush=True)
    publish(report(rows, args.steps), "warm-start-energy", args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
