#!/usr/bin/env python3
"""The discharge rate of tools/peer_lammps_silo.py's silo over several fills, with and
without substeps (Rules.substeps) or other settings, and LAMMPS's: how much the rate of
this short discharge varies from one trajectory to the next, against how much a setting
(or the other code) moves it.

For each lattice seed (tools/silo.py ``fill_positions``: the same silo, another
jitter) the fill is settled with the orifice closed at the defaults, then discharged
through the orifice with each variant (a name and tools/silo.py options, default: the
defaults and the former defaults, plain sweeps at 100 / 100 without substeps); the steady rate is fitted as in tools/silo.py
(``steady_rate``). With ``--lammps``, LAMMPS settles and discharges each seed's lattice
as in tools/peer_lammps_silo.py. Reported: each rate; per variant the mean, standard
deviation and standard error of the mean over the seeds, and the mean wall seconds per
simulated second of the discharge. 1 thread per run; ``--jobs`` fills run side by side
(their wall times then share the machine).

    python tools/silo_seeds.py --write         # ~10 min on 2 cores
    python tools/silo_seeds.py --seeds 1 2 3 --jobs 2 --section silo-steps --write \\
        --variants "defaults=" "step 0.05=--step-fraction 0.05" "substeps=--substeps"
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import math
import multiprocessing
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import peer_lammps_silo  # noqa: E402  (tools/peer_lammps_silo.py)
import silo  # noqa: E402  (tools/silo.py)
from machine import FORMER_DEFAULTS, cpu_name, tuning_text, write_section  # noqa: E402

#: --variants default: NAME=OPTIONS (tools/silo.py options)
#: the defaults, and the former ones (tools/machine.py FORMER_DEFAULTS)
VARIANTS = ["defaults=", "former defaults=--tuning " + tuning_text(FORMER_DEFAULTS)]
#: the row name of LAMMPS's rates (--lammps)
LAMMPS = "LAMMPS"


def rate(a, settled) -> tuple:
    """(steady discharge rate [kg/s], wall s per simulated s) of the settled fill's
    discharge under options ``a``."""
    times, mass, wall, _ = silo.discharge(a, settled, a.orifice * a.radius)
    w = silo.steady_rate(times, mass, silo.total_mass(a, len(settled[0])), a.transient)[0]
    return w, wall / (times[-1] - times[0])


def lammps_rate(a, seed: int) -> tuple:
    """The same for LAMMPS from seed's lattice (tools/peer_lammps_silo.py)."""
    c = a.silo_radius + 0.005
    x = silo.fill_positions(a.silo_radius, a.radius, a.fill, 0.05, np.array([c, c]), seed)
    times, mass, wall, _, _ = peer_lammps_silo.lammps_run(a, x)
    return silo.steady_rate(times, mass, silo.total_mass(a, len(x)), a.transient)[0], wall / a.duration


def parse_variant(text: str) -> tuple:
    """("name", [options]) from "name=options" (options split on blanks)."""
    name, sep, opts = text.partition("=")
    if not sep or not name.strip() or name.strip() == LAMMPS:
        raise ValueError(f"a variant is NAME=OPTIONS (NAME not {LAMMPS}), got {text!r}")
    return name.strip(), opts.split()


def seed_rates(seed: int, variants, lammps: bool = False) -> list:
    """(rate [kg/s], wall s per simulated s) of each variant's discharge of fill
    ``seed``, then LAMMPS's if ``lammps``."""
    base = peer_lammps_silo.settings([])
    settled = silo.settled_fill(base, base.fill, seed=seed)
    out = []
    for name, opts in variants:
        out.append(rate(peer_lammps_silo.settings(opts), settled))
        print(seed, name, out[-1], flush=True)
    if lammps:
        out.append(lammps_rate(base, seed))
        print(seed, LAMMPS, out[-1], flush=True)
    return out


def command(seeds, variants, lammps=False, jobs=1) -> str:
    """The command line that reproduces a report."""
    cmd = f"python tools/silo_seeds.py --seeds {' '.join(map(str, seeds))}"
    if [f"{n}={' '.join(o)}" for n, o in variants] != VARIANTS:
        cmd += " --variants " + " ".join(f'"{n}={" ".join(o)}"' for n, o in variants)
    return cmd + (" --lammps" if lammps else "") + (f" --jobs {jobs}" if jobs > 1 else "")


def report(seeds, rows, variants=None, jobs=1) -> str:
    """The markdown section; rows: {name: [(rate [kg/s], wall s per sim s) per seed]}."""
    variants = variants or [parse_variant(v) for v in VARIANTS]
    share = f", {jobs} runs at a time" if jobs > 1 else ""
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread per run{share}: "
             f"`{command(seeds, variants, LAMMPS in rows, jobs)}`", "",
             "tools/peer_lammps_silo.py's silo (orifice 5 d, discharge 0.6 s), fills from "
             "other lattice jitters; steady rate [kg/s], and the wall time per simulated "
             "second of the discharge:", "",
             "| settings | " + " | ".join(f"seed {s}" for s in seeds) +
             " | mean | std | std error of the mean | wall s / sim s |",
             "|---|" + "---|" * (len(seeds) + 4)]
    for name, runs in rows.items():
        rates = [r for r, _ in runs]
        std = np.std(rates, ddof=1)
        lines.append(f"| {name} | " + " | ".join(f"{r:.4f}" for r in rates) +
                     f" | {np.mean(rates):.4f} | {std:.4f} | {std / math.sqrt(len(rates)):.4f}"
                     f" | {np.mean([w for _, w in runs]):.1f} |")
    return "\n".join(lines) + "\n"


def parse(argv=None):
    """The options, checked (usage errors before any run)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--variants", nargs="+", default=VARIANTS, metavar="NAME=OPTIONS",
                    help="settings to discharge each fill with: a name and tools/silo.py "
                         "options (empty: the defaults)")
    ap.add_argument("--lammps", action="store_true", help="LAMMPS's rate for each fill too")
    ap.add_argument("--jobs", type=int, default=1, help="fills run side by side")
    ap.add_argument("--section", default="silo-seeds",
                    help="the section of docs/granular.md to write")
    ap.add_argument("--write", action="store_true", help="write docs/granular.md's section")
    args = ap.parse_args(argv)
    if len(args.seeds) < 2:
        ap.error("--seeds needs at least two seeds (a spread)")
    if args.jobs < 1:
        ap.error(f"--jobs must be >= 1, got {args.jobs}")
    args.variants = checked_variants(ap, args.variants)
    return args


def checked_variants(ap, texts) -> list:
    """[(name, options)] of NAME=OPTIONS texts, each name and its tools/silo.py options
    checked: a usage error from ``ap`` before any run."""
    try:
        variants = [parse_variant(v) for v in texts]
    except ValueError as exc:
        ap.error(str(exc))
    for name, opts in variants:
        try:
            peer_lammps_silo.settings(opts)
        except SystemExit:             # tools/silo.py's parser said what is wrong
            ap.error(f"variant {name!r}: options tools/silo.py does not take")
    return variants


def main(argv=None):
    args = parse(argv)
    variants = args.variants
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(args.jobs, mp_context=ctx) as pool:
        per_seed = list(pool.map(seed_rates, args.seeds, [variants] * len(args.seeds),
                                 [args.lammps] * len(args.seeds)))
    names = [name for name, _ in variants] + ([LAMMPS] if args.lammps else [])
    rows = {name: [r[i] for r in per_seed] for i, name in enumerate(names)}
    text = report(args.seeds, rows, variants, args.jobs)
    print(text)
    if args.write:
        write_section(os.path.join(silo.DOCS, "granular.md"), args.section, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
