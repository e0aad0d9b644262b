#!/usr/bin/env python3
"""What each contact-solver setting buys and costs, on the two scenes that decide the
defaults: the pour's bed (speed, overlaps, kinetic energy) and a heavy ball landing on
a settled block in a new Simulation (energy growth).

For each named setting (``NAME=FIELD=VALUE ...``, Tuning fields):

- the pour (scenes/pour.toml) from 1 s to 2 s on 1 thread, steps one by one
  (tools/step_overlaps.py ``run``): wall s per simulated s of the steps alone, the
  largest brute-force overlap / diameter after any step, sweeps per solve, kinetic
  energy / initial energy at 2 s;
- a ball 8x heavier dropped onto the 256-sphere FCC block settled under the same
  setting, frictionless (tools/warm_start_energy.py ``drop``): the largest growth of
  the total energy in one of the next 300 steps / the ball's impact energy, and the
  step. Its first step starts the solver cold (a new Simulation has no warm start).

    python tools/settings_tradeoff.py --write         # ~10 min on 1 core
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)
from step_overlaps import parse_variant, run  # noqa: E402  (tools/step_overlaps.py)
from warm_start_energy import drop, settled_block  # noqa: E402

#: --variants default
VARIANTS = [
    "defaults=",
    "substeps=substeps=True",
    "ω 1.8, substeps=relaxation=1.8 substeps=True",
    "ω 1.8, 60 / 60, substeps=relaxation=1.8 contact_iterations=60 position_iterations=60 "
    "substeps=True",
    "ω 1.8, 40 / 40, shock, substeps=relaxation=1.8 contact_iterations=40 "
    "position_iterations=40 shock_propagation=on substeps=True",
]


def measure(name: str, changes: dict, every: int) -> dict:
    """The pour's bed and the heavy ball under Tuning().with_(**changes)."""
    scene = ts.load_scene(os.path.join(ROOT, "scenes", "pour.toml"))
    bed = run(scene, 1.0, 2.0, every, changes)
    tuning = Tuning().with_(**changes)
    block, settled = settled_block(0.0, tuning)
    ball = drop(block, settled, 8.0, "auto", 300, tuning)
    print(name, bed, ball, flush=True)
    return dict(bed, ball=ball["growth"], ball_step=ball["step"])


def report(args, rows) -> str:
    """The markdown section."""
    extra = "" if args.variants == VARIANTS else \
        " --variants " + " ".join(f'"{v}"' for v in args.variants)
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: `python "
             f"tools/settings_tradeoff.py{extra}{' --write' if args.write else ''}`.", "",
             "Pour's bed [1, 2] s (steps one by one; brute-force overlap after "
             f"{'every step' if args.every == 1 else f'every {args.every}th step'}); a ball 8x "
             "heavier dropped onto the settled 256-sphere block, frictionless, largest "
             "one-step growth of the total energy / its impact energy (and the step; step 1 "
             "is the cold start of a new Simulation):", "",
             "| settings | bed wall s / sim s | bed overlap / d, largest | sweeps per solve "
             "(velocity / position) | K(2 s) / E0 | heavy ball: energy growth / impact "
             "energy (step) |", "|---|---|---|---|---|---|"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['wall']:.3g} | {r['brute']:.2e} | {r['velocity']:.0f} / "
                     f"{r['position']:.0f} | {r['kinetic']:.1e} | {r['ball']:.1e} "
                     f"({r['ball_step']}) |")
    lines.append("")
    for v in args.variants:
        name, changes = parse_variant(v)
        lines.append(f"- {name}: `Tuning().with_("
                     f"{', '.join(f'{k}={x!r}' for k, x in changes.items())})`")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", default=VARIANTS, metavar="NAME=CHANGES")
    ap.add_argument("--every", type=int, default=1, help="check overlaps after every N-th step")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--section", default="settings-tradeoff", help="docs/bench.md section")
    args = ap.parse_args(argv)
    try:
        variants = [parse_variant(v) for v in args.variants]
    except ValueError as err:
        ap.error(str(err))
    rows = {name: measure(name, changes, args.every) for name, changes in variants}
    publish(report(args, rows), args.section, args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
