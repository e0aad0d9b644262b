#!/usr/bin/env python3
"""Overlaps after a step, measured brute force, against what stats["max_overlap"]
reports, without and with substeps (Rules.substeps).

stats["max_overlap"] is the largest overlap after a step: the contact solver measures
it on its rows and, for the spheres of impacts to come (apart and approaching faster
than the impact speed: no row), over their full stencil, walls and objects
(contacts/overlaps.py). Such overlaps arise where a sphere the solve stops is moved by
its position update (the trapezoidal move) into a neighbour or wall about to hit it;
with substeps those pairs get rows for the position pass (docs/algorithm.md,
"Substeps"). This tool checks the measurement: it runs a scene to --duration on 1
thread with the defaults and with substeps, and after every --every-th step measures
the largest pair or wall overlap / diameter over all pairs brute force
(tools/contact_solver.py ``max_overlap``), against what the steps reported.

    python tools/step_overlaps.py --write            # ~1 min on 1 core
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from contact_solver import max_overlap  # noqa: E402  (tools/contact_solver.py)
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)


def run(scene, start: float, duration: float, every: int, substeps: bool) -> dict:
    """Over the steps ending in [start, duration]: the largest brute-force overlap after
    a sampled step (and when) and the largest last_step["max_overlap"] (every step);
    steps and substeps in all, wall seconds (checks included)."""
    sim = ts.Simulation(scene, threads=1, tuning=Tuning().with_(substeps=substeps))
    worst, when, reported, t0 = 0.0, 0.0, 0.0, time.perf_counter()
    sim.advance_to(start)
    while sim.time < duration:
        sim.step_toward(duration)
        reported = max(reported, sim.last_step["max_overlap"])
        if sim.stats["steps"] % every == 0:
            now = max_overlap(sim.state(), scene)
            if now > worst:
                worst, when = now, sim.time
    return dict(brute=worst, when=when, reported=reported, steps=sim.stats["steps"],
                substeps=sim.stats["substeps"], wall=time.perf_counter() - t0)


def report(args, rows) -> str:
    """The markdown section."""
    extra = (f" --start {args.start:g}" if args.start else "") + \
        (f" --every {args.every}" if args.every != 5 else "") + \
        (f" --section {args.section}" if args.section != "step-overlaps" else "")
    after = "every step" if args.every == 1 else f"every {args.every}th step"
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: `python "
             f"tools/step_overlaps.py{extra}{' --write' if args.write else ''}`.", "",
             f"`{args.scene}` to {args.duration:g} s; over the steps from {args.start:g} s on, "
             f"the largest pair or wall overlap / diameter over all pairs after {after}, "
             "and the largest overlap a step reported (`last_step[\"max_overlap\"]`, every "
             "step):", "",
             "| settings | brute force, largest (at t [s]) | reported by the steps | steps | "
             "substeps |", "|---|---|---|---|---|"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['brute']:.2e} ({r['when']:.3f}) | {r['reported']:.2e} | "
                     f"{r['steps']} | {r['substeps']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=os.path.join("scenes", "pour.toml"))
    ap.add_argument("--start", type=float, default=0.0, help="measure from this time [s]")
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--every", type=int, default=5, help="check after every N-th step")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--section", default="step-overlaps", help="docs/bench.md section")
    args = ap.parse_args(argv)
    if not 0 <= args.start < args.duration or args.every < 1:
        ap.error("need 0 <= --start < --duration and --every >= 1")
    scene = ts.load_scene(os.path.join(ROOT, args.scene))
    rows = {}
    for name, substeps in (("defaults", False), ("substeps", True)):
        rows[name] = run(scene, args.start, args.duration, args.every, substeps)
        print(name, rows[name], flush=True)
    publish(report(args, rows), args.section, args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
