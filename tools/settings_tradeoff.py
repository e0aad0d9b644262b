#!/usr/bin/env python3
"""What each contact-solver setting buys and costs, on the two scenes that decide the
defaults: the pour's bed (speed, overlaps, kinetic energy) and a heavy ball landing on
a settled block in a new Simulation (energy growth).

For each named setting (``NAME=FIELD=VALUE ...``: Tuning fields, and the Simulation's
``step_fraction``):

- the pour (scenes/pour.toml) from 1 s to 2 s on 1 thread, steps one by one
  (tools/step_overlaps.py ``run``): wall s per simulated s of the steps alone, the
  largest brute-force overlap / diameter after any step, sweeps per solve, kinetic
  energy / initial energy at 2 s;
- a ball 8x heavier dropped onto the 256-sphere FCC block settled under the same
  setting, frictionless (tools/warm_start_energy.py ``drop``): the largest growth of
  the total energy in one of the next 300 steps / the ball's impact energy, and the
  step. Its first step starts the solver cold (a new Simulation has no warm start);
- the same 256-sphere block settling from its lattice (neighbours 1e-6 diameters
  apart), 150 steps: how far the total energy ever rises above its start / the start
  (0: never; a dissipative scene, where it should never rise);
- the pour's bed over ``--fills`` fills (the pour's ``seed`` 1..K, each run to 1 s,
  then its bed [1, 2] s timed with ``advance_to``): summed wall s per simulated s and
  the range over the fills, the fall [0, 1] s summed likewise, the largest overlap the
  solver reported after a step of each bed (the bed run again step by step, untimed;
  largest and median over the fills), and each fill's kinetic
  energy at 2 s / its initial energy (median, range, how many are at most 1e-6: a
  bed's K(2 s) scatters by 10-30x between fills). A bed is chaotic (a setting changes
  its trajectory, and one fill's bed takes +-20 % steps with it): the summed figures
  are the ones to compare.

    python tools/settings_tradeoff.py --write         # ~20 min on 1 core
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.builders import fcc_block  # noqa: E402
from machine import FORMER_DEFAULTS, cpu_name, publish, tuning_text  # noqa: E402
from step_overlaps import (parse_variant, run, simulation_options,  # noqa: E402
                           variant_text)  # (tools/step_overlaps.py)
from warm_start_energy import drop, settled_block  # noqa: E402
from bed_steps import pour_fill  # noqa: E402  (tools/bed_steps.py)

#: --variants default: the former defaults, and over-relaxed sweeps with substeps at
#: several caps (the defaults are 100 / 60)
VARIANTS = [
    "former defaults: plain, 100 / 100=" + tuning_text(FORMER_DEFAULTS),
    "ω 1.8, 100 / 100, substeps=relaxation=1.8 contact_iterations=100 "
    "position_iterations=100 substeps=True",
    "ω 1.8, 80 / 80, substeps=relaxation=1.8 contact_iterations=80 position_iterations=80 "
    "substeps=True",
    "ω 1.8, 100 / 60, substeps=relaxation=1.8 contact_iterations=100 "
    "position_iterations=60 substeps=True",
    "ω 1.8, 60 / 60, substeps=relaxation=1.8 contact_iterations=60 position_iterations=60 "
    "substeps=True",
]


#: --fills default
FILLS = 8


def block_energy_rise(options: dict, steps: int = 150) -> float:
    """The 256-sphere FCC block settling from its lattice under Simulation keywords
    ``options`` (step_overlaps.simulation_options): the largest total energy above the
    start over ``steps`` steps / the start energy (0 if never)."""
    sim = ts.Simulation(fcc_block((4, 4, 4), radius=0.01, restitution=0.5), threads=1,
                        **options)
    start = highest = sim.energy_budget()["current"]
    for _ in range(steps):
        sim.advance(sim.max_step())
        highest = max(highest, sim.energy_budget()["current"])
    return (highest - start) / abs(start)


def pour_fills(changes: dict, fills: int) -> dict:
    """The pour over fills seed = 1..fills under ``changes`` (simulation_options): its bed
    [1, 2] s (``bed``: summed wall s per simulated s, ``fastest`` and ``slowest`` fill,
    ``steps`` summed), its fall [0, 1] s (``fall``: summed wall s per simulated s), the
    kinetic energy at 2 s / the initial energy (``kinetic``: one per fill) and the
    largest overlap the solver reported after a step of the bed / contact distance
    (``overlaps``: one per fill; the bed run again from 1 s step by step, untimed: the
    same steps, simulation.step_toward)."""
    walls, falls, kinetic, overlaps, steps = [], [], [], [], 0
    for seed in range(1, fills + 1):
        sim = ts.Simulation(pour_fill(seed), threads=1, **simulation_options(changes))
        start = sim.checkpoint()            # one untimed step compiles (or loads) the
        sim.advance(sim.max_step())         # step's kernels; the fill then starts anew
        sim.restore(start)
        t0 = time.perf_counter()
        sim.advance_to(1.0)
        falls.append(time.perf_counter() - t0)
        settled = sim.checkpoint()
        s0, t0 = sim.stats["steps"], time.perf_counter()
        sim.advance_to(2.0)
        walls.append(time.perf_counter() - t0)
        steps += sim.stats["steps"] - s0
        budget = sim.energy_budget()
        kinetic.append(budget["kinetic"] / budget["initial"])
        overlaps.append(bed_overlap(sim, settled, 2.0))
    return dict(bed=sum(walls) / fills, fastest=min(walls), slowest=max(walls), steps=steps,
                fall=sum(falls) / fills, kinetic=kinetic, overlaps=overlaps)


def bed_overlap(sim, start, t_end: float) -> float:
    """The largest overlap / contact distance the solver reported after any step from
    checkpoint ``start`` to ``t_end`` [s] (stats' max_overlap of each step), stepping
    as advance_to does."""
    sim.restore(start)
    worst = 0.0
    while sim.step_toward(t_end) > 0:
        worst = max(worst, sim.last_step["max_overlap"])
    return worst


def measure(name: str, changes: dict, every: int, fills: int) -> dict:
    """The pour's bed, the heavy ball, the settling block and the fills under
    ``changes`` (Tuning fields and step_fraction: simulation_options)."""
    scene = ts.load_scene(os.path.join(ROOT, "scenes", "pour.toml"))
    bed = run(scene, 1.0, 2.0, every, changes)
    options = simulation_options(changes)
    block, settled = settled_block(0.0, options["tuning"], options.get("step_fraction"))
    ball = drop(block, settled, 8.0, "auto", 300, options["tuning"],
                options.get("step_fraction"))
    rise = block_energy_rise(options)
    many = pour_fills(changes, fills) if fills else None
    print(name, bed, ball, rise, many, flush=True)
    return dict(bed, ball=ball["growth"], ball_step=ball["step"], rise=rise, fills=many)


def report(args, rows) -> str:
    """The markdown section."""
    extra = "" if args.variants == VARIANTS else \
        " --variants " + " ".join(f'"{v}"' for v in args.variants)
    fills = f"--fills {args.fills}" if args.fills != FILLS else ""
    name = getattr(args, "section", "settings-tradeoff")
    section = f"--section {name}" if name != "settings-tradeoff" else ""
    extra = " ".join(x for x in (extra.strip(), fills, section) if x)
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: `python "
             f"tools/settings_tradeoff.py{' ' + extra if extra else ''}"
             f"{' --write' if args.write else ''}`.", "",
             "Pour's bed [1, 2] s (steps one by one; brute-force overlap after "
             f"{'every step' if args.every == 1 else f'every {args.every}th step'})"
             + (f", and over {args.fills} fills (seed 1..{args.fills}; summed, and the "
                "fastest and slowest fill; their kinetic energies at 2 s; the largest overlap "
                "the solver reported after a step of each bed; their falls [0, 1] "
                "s summed)" if args.fills else "")
             + "; a ball 8x heavier dropped onto the settled 256-sphere block, "
             "frictionless, largest one-step growth of the total energy / its impact energy "
             "(and the step; step 1 is the cold start of a new Simulation); the block "
             "settling from its lattice, largest rise of its total energy above the start "
             "/ the start (0: never):", "",
             "| settings | bed wall s / sim s | over the fills (fastest-slowest) | bed overlap "
             "/ d, largest | bed overlap / d over the fills: largest (median), fills above "
             "1e-4 | sweeps per "
             "solve (velocity / position) | K(2 s) / E0 | K(2 s) / "
             "E0 over the fills: median (lowest-highest), fills at most 1e-6 | fall wall s / "
             "sim s over the fills | heavy ball: energy growth / impact energy (step) | "
             "block settling: energy rise |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        many = k_fills = fall = o_fills = ""
        if r["fills"] is not None:
            f = r["fills"]
            many = f"{f['bed']:.3g} ({f['fastest']:.3g}-{f['slowest']:.3g})"
            fall = f"{f['fall']:.3g}"
            k = sorted(f["kinetic"])
            k_fills = (f"{statistics.median(k):.1e} ({k[0]:.1e}-{k[-1]:.1e}), "
                       f"{sum(x <= 1e-6 for x in k)} of {len(k)}")
            o = f["overlaps"]
            o_fills = (f"{max(o):.2e} ({statistics.median(o):.1e}), "
                       f"{sum(x > 1e-4 for x in o)} of {len(o)}")
        lines.append(f"| {name} | {r['wall']:.3g} | {many} | {r['brute']:.2e} | {o_fills} | "
                     f"{r['velocity']:.0f} / {r['position']:.0f} | {r['kinetic']:.1e} | {k_fills} | "
                     f"{fall} | "
                     f"{r['ball']:.1e} ({r['ball_step']}) | {r['rise']:.1e} |")
    lines.append("")
    for v in args.variants:
        name, changes = parse_variant(v)
        lines.append(f"- {name}: `{variant_text(changes)}`")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", default=VARIANTS, metavar="NAME=CHANGES")
    ap.add_argument("--every", type=int, default=1, help="check overlaps after every N-th step")
    ap.add_argument("--fills", type=int, default=FILLS,
                    help="pour fills whose beds are timed (0: none)")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--section", default="settings-tradeoff", help="docs/bench.md section")
    args = ap.parse_args(argv)
    if args.fills < 0:
        ap.error("--fills must be >= 0")
    try:
        variants = [parse_variant(v) for v in args.variants]
    except ValueError as err:
        ap.error(str(err))
    rows = {name: measure(name, changes, args.every, args.fills) for name, changes in variants}
    publish(report(args, rows), args.section, args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
