#!/usr/bin/env python3
"""Which steps of a pour's bed leave the most overlap, and what the position pass did
in them.

Runs scenes/pour.toml with its ``seed`` set to --seed (the fills of
tools/settings_tradeoff.py are seeds 1..8) to --start s, then steps it one by one to
--end s (1 thread, f64) under --step-fraction and --tuning, and lists every step that
leaves an overlap (stats' max_overlap of the step / contact distance) above
--threshold: its time and length, the velocity and position sweeps it ran against the
position cap, and the position pass's last residual (the largest overlap a row had
when its last sweep came to it, per step [m/s]: contacts/pgs.py update_from) times
the step over the smallest diameter, the quantity its sweeps stop on, beside the
overlap the step left. Ends with the largest overlap of the phase.

    python tools/bed_steps.py --seed 1 --step-fraction 0.2 --tuning position_iterations=100
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, step_fraction_arg, tuning_args  # noqa: E402


def pour_fill(seed: int):
    """scenes/pour.toml with ``seed = seed``."""
    text = open(os.path.join(ROOT, "scenes", "pour.toml")).read()
    filled, found = re.subn(r"(?m)^seed = [0-9]+$", f"seed = {seed}", text)
    if found != 1:
        raise RuntimeError("scenes/pour.toml has no single 'seed = N' line to vary")
    with tempfile.NamedTemporaryFile("w", suffix=".toml") as f:
        f.write(filled)
        f.flush()
        return ts.load_scene(f.name)


def steps_above(sim, end: float, threshold: float) -> tuple:
    """([(t, h, velocity sweeps, position sweeps, position cap, residual x h / d,
    overlap)] of the steps to ``end`` that leave more than ``threshold``, the largest
    overlap of all steps)."""
    solver = sim.debug_view().solver
    d = 2.0 * float(sim.scene.radius.min())
    rows, worst = [], 0.0
    while sim.step_toward(end) > 0:
        step = sim.last_step
        worst = max(worst, step["max_overlap"])
        if step["max_overlap"] > threshold:
            rows.append((sim.time, step["h"], step["contact_iterations"],
                         step["position_iterations"], int(solver.cap_w[None]),
                         float(solver.residual[None]) * step["h"] / d, step["max_overlap"]))
    return rows, worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=3, help="the pour's seed (its file: 3)")
    ap.add_argument("--start", type=float, default=1.0)
    ap.add_argument("--end", type=float, default=2.0)
    ap.add_argument("--threshold", type=float, default=8e-5,
                    help="list the steps leaving more overlap / contact distance")
    ap.add_argument("--step-fraction", type=float, default=None)
    ap.add_argument("--tuning", nargs="+", default=None, metavar="NAME=VALUE")
    args = ap.parse_args(argv)
    if not 0 <= args.start < args.end:
        ap.error("--start must be >= 0 and < --end")
    options = step_fraction_arg(args.step_fraction, ap)
    tuning = tuning_args(args.tuning, ap)
    sim = ts.Simulation(pour_fill(args.seed), threads=1, precision="f64",
                        tuning=Tuning().with_(**tuning), **options)
    if sim.debug_view().solver is None:
        ap.error("the pour runs without a contact solver under these settings")
    sim.advance_to(args.start)
    rows, worst = steps_above(sim, args.end, args.threshold)
    print(f"{cpu_name()}, 1 thread, f64: pour seed {args.seed}, [{args.start}, {args.end}] s, "
          f"step_fraction {sim.step_fraction}, tuning {tuning or 'defaults'}")
    print("| t [s] | h [s] | velocity sweeps | position sweeps (cap) | position residual x h / d "
          "| overlap / d |")
    print("|---|---|---|---|---|---|")
    for t, h, vel, pos, cap, res, over in rows:
        print(f"| {t:.4f} | {h:.2e} | {vel} | {pos} ({cap}) | {res:.2e} | {over:.2e} |")
    print(f"largest overlap after a step: {worst:.3e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
