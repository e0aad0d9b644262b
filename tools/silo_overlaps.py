#!/usr/bin/env python3
"""When a discharging silo's largest overlaps happen: the LAMMPS-comparison silo
(tools/peer_lammps_silo.py) settled, then discharged step by step in a new Simulation
(no warm start: its first solve starts cold), with the largest overlap after a step
(``last_step["max_overlap"]``, over every pair, wall and object) in the first steps
and over the rest of the discharge.

    python tools/silo_overlaps.py --write                # defaults, former defaults; ~3 min
    python tools/silo_overlaps.py --variants "defaults=" "fine=--step-fraction 0.05"
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import peer_lammps_silo  # noqa: E402  (tools/peer_lammps_silo.py)
import silo  # noqa: E402  (tools/silo.py)
import silo_seeds  # noqa: E402  (tools/silo_seeds.py: its variants)
from machine import FORMER_DEFAULTS, cpu_name, tuning_text, write_section  # noqa: E402

#: --variants default: NAME=OPTIONS (tools/silo.py options)
#: the defaults, and the former ones (tools/machine.py FORMER_DEFAULTS)
VARIANTS = ["defaults=", "former defaults=--tuning " + tuning_text(FORMER_DEFAULTS)]


def overlaps(options, first: int) -> dict:
    """The discharge under tools/silo.py ``options``: the largest overlap after each of
    the first ``first`` steps, the largest after them (and when), steps in all."""
    a = peer_lammps_silo.settings(options)
    settled = silo.settled_fill(a, a.fill, seed=1)
    sim = silo.discharging(a, settled, a.orifice * a.radius)
    early, late, when = [], 0.0, 0.0
    while sim.time < a.duration - 1e-12:
        sim.step_toward(a.duration)
        now = sim.last_step["max_overlap"]
        if len(early) < first:
            early.append(now)
        elif now > late:
            late, when = now, sim.time
    return dict(early=early, late=late, when=when, steps=sim.stats["steps"])


def report(variants, rows, first: int, command: str) -> str:
    """The markdown section."""
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: `{command}`", "",
             "The silo of tools/peer_lammps_silo.py (fill 1), discharged in a new Simulation "
             "(its first solve starts cold); largest overlap after a step / contact "
             f"distance, in each of the first {first} steps and over the rest:", "",
             f"| settings | first {first} steps | after them (at t [s]) | steps |",
             "|---|---|---|---|"]
    for name, _ in variants:
        r = rows[name]
        lines.append(f"| {name} | {', '.join(f'{o:.1e}' for o in r['early'])} | "
                     f"{r['late']:.1e} ({r['when']:.3f}) | {r['steps']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", default=VARIANTS, metavar="NAME=OPTIONS")
    ap.add_argument("--first", type=int, default=5, help="steps reported one by one")
    ap.add_argument("--write", action="store_true", help="write docs/granular.md's section")
    ap.add_argument("--section", default="silo-overlaps")
    args = ap.parse_args(argv)
    if args.first < 1:
        ap.error("--first must be >= 1")
    variants = silo_seeds.checked_variants(ap, args.variants)
    rows = {name: overlaps(opts, args.first) for name, opts in variants}
    command = "python tools/silo_overlaps.py " + " ".join(argv)
    text = report(variants, rows, args.first, command.strip())
    print(text)
    if args.write:
        write_section(os.path.join(HERE, "..", "docs", "granular.md"), args.section, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
