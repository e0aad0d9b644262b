#!/usr/bin/env python3
"""The discharge rate of tools/peer_lammps_silo.py's silo over several fills, with and
without substeps (Rules.substeps): how much the rate of this short discharge varies
from one trajectory to the next, against how much substeps move it.

For each lattice seed (tools/silo.py ``fill_positions``: the same silo, another
jitter) the fill is settled with the orifice closed, then discharged through the
orifice with the defaults and with substeps; the steady rate is fitted as in
tools/silo.py (``steady_rate``). Reported: each rate, and per setting their mean and
standard deviation over the seeds. 1 thread.

    python tools/silo_seeds.py --write         # ~10 min on 2 cores
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import peer_lammps_silo  # noqa: E402  (tools/peer_lammps_silo.py)
import silo  # noqa: E402  (tools/silo.py)
from machine import cpu_name, write_section  # noqa: E402


def rate(a, settled) -> float:
    """Steady discharge rate [kg/s] of the settled fill under options ``a``."""
    times, mass, _, sim = silo.discharge(a, settled, a.orifice * a.radius)
    total = len(settled[0]) * 2500.0 * 4 / 3 * math.pi * a.radius ** 3
    return silo.steady_rate(times, mass, total, a.transient)[0]


def report(seeds, rows) -> str:
    """The markdown section."""
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread: `python "
             f"tools/silo_seeds.py --seeds {' '.join(map(str, seeds))}`", "",
             "tools/peer_lammps_silo.py's silo (orifice 5 d, discharge 0.6 s), fills from "
             "other lattice jitters; steady rate [kg/s]:", "",
             "| settings | " + " | ".join(f"seed {s}" for s in seeds) + " | mean | std |",
             "|---|" + "---|" * (len(seeds) + 2)]
    for name, rates in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{r:.4f}" for r in rates) +
                     f" | {np.mean(rates):.4f} | {np.std(rates, ddof=1):.4f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--write", action="store_true", help="write docs/granular.md's section")
    args = ap.parse_args(argv)
    if len(args.seeds) < 2:
        ap.error("--seeds needs at least two seeds (a spread)")
    base = peer_lammps_silo.settings([])
    sub = peer_lammps_silo.settings(["--substeps"])
    rows = {"defaults": [], "substeps": []}
    for seed in args.seeds:
        settled = silo.settled_fill(base, base.fill, seed=seed)
        rows["defaults"].append(rate(base, settled))
        rows["substeps"].append(rate(sub, settled))
        print(seed, rows["defaults"][-1], rows["substeps"][-1], flush=True)
    text = report(args.seeds, rows)
    print(text)
    if args.write:
        write_section(os.path.join(silo.DOCS, "granular.md"), "silo-seeds", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
