#!/usr/bin/env python3
"""Overlaps after a step, measured brute force, against what stats["max_overlap"]
reports, for named settings (default: the defaults and the former defaults, plain
sweeps at 100 / 100 without substeps), with their
wall time, sweeps per step and kinetic energy at the end.

stats["max_overlap"] is the largest overlap after a step: the contact solver measures
it on its rows and, for the spheres of impacts to come (apart and approaching faster
than the impact speed: no row), over their full stencil, walls and objects
(contacts/overlaps.py). Such overlaps arise where a sphere the solve stops is moved by
its position update (the trapezoidal move) into a neighbour or wall about to hit it;
with substeps those pairs get rows for the position pass (docs/algorithm.md,
"Substeps"). This tool checks the measurement: it runs a scene to --duration on 1
thread with each setting (--variants), and after every --every-th step measures
the largest pair or wall overlap / diameter over all pairs brute force
(tools/contact_solver.py ``max_overlap``), against what the steps reported.

    python tools/step_overlaps.py --write            # ~1 min on 1 core
    python tools/step_overlaps.py --start 1 --every 1 \\
        --variants "defaults=" "fast=relaxation=1.8 contact_iterations=40 substeps=True"
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
from machine import (FORMER_DEFAULTS, cpu_name, publish, step_fraction_option,  # noqa: E402
                     tuning_code, tuning_text)


def simulation_options(changes: dict) -> dict:
    """Simulation keywords of a variant's ``changes``: ``step_fraction`` (a Simulation
    argument) if it names one, and ``tuning``, Tuning().with_ the other fields."""
    fields = dict(changes)
    return dict(step_fraction_option(fields.pop("step_fraction", None)),
                tuning=Tuning().with_(**fields))


def variant_text(changes: dict) -> str:
    """How a variant's ``changes`` build its Simulation, as code."""
    fields = dict(changes)
    sf = fields.pop("step_fraction", None)
    text = tuning_code(fields)
    return text if sf is None else f"step_fraction={sf!r}, tuning={text}"


def run(scene, start: float, duration: float, every: int, changes: dict) -> dict:
    """Over the steps ending in [start, duration] with ``changes`` (Tuning fields, and
    the Simulation's step_fraction: simulation_options):
    the largest brute-force overlap after a sampled step (and when), the largest
    last_step["max_overlap"] (every step), wall seconds per simulated second of the
    steps alone (checks not timed), velocity and position sweeps per contact step,
    sweep-limit hits, and kinetic energy / initial total energy at ``duration``."""
    sim = ts.Simulation(scene, threads=1, **simulation_options(changes))
    e0 = ts.observe.total_energy(sim.state(), scene.gravity)
    worst, when, reported, stepping = 0.0, 0.0, 0.0, 0.0
    sim.advance_to(start)
    before = dict(sim.stats)
    while sim.time < duration:
        t0 = time.perf_counter()
        sim.step_toward(duration)
        stepping += time.perf_counter() - t0
        reported = max(reported, sim.last_step["max_overlap"])
        if sim.stats["steps"] % every == 0:
            now = max_overlap(sim.state(), scene)
            if now > worst:
                worst, when = now, sim.time
    done = {k: sim.stats[k] - before[k] for k in
            ("steps", "substeps", "contact_steps", "contact_iterations",
             "position_iterations", "sweep_limit_hits")}
    solves = max(done["contact_steps"], 1)
    return dict(brute=worst, when=when, reported=reported, steps=sim.stats["steps"],
                substeps=sim.stats["substeps"], wall=stepping / (duration - start),
                velocity=done["contact_iterations"] / solves,
                position=done["position_iterations"] / solves,
                hits=done["sweep_limit_hits"],
                kinetic=ts.observe.kinetic_energy(sim.state()) / e0)


def report(args, rows) -> str:
    """The markdown section."""
    extra = (f" --start {args.start:g}" if args.start else "") + \
        (f" --every {args.every}" if args.every != 5 else "") + \
        (f" --section {args.section}" if args.section != "step-overlaps" else "") + \
        (" --variants " + " ".join(f'"{v}"' for v in args.variants)
         if args.variants != VARIANTS else "")
    after = "every step" if args.every == 1 else f"every {args.every}th step"
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: `python "
             f"tools/step_overlaps.py{extra}{' --write' if args.write else ''}`.", "",
             f"`{args.scene}` to {args.duration:g} s; over the steps from {args.start:g} s on, "
             f"the largest pair or wall overlap / diameter over all pairs after {after}, "
             "and the largest overlap a step reported (`last_step[\"max_overlap\"]`, every "
             "step):", "",
             "| settings | brute force, largest (at t [s]) | reported by the steps | steps | "
             "substeps | wall s / sim s | sweeps per solve (velocity / position) | "
             "sweep-limit hits | K(end) / E0 |", "|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['brute']:.2e} ({r['when']:.3f}) | {r['reported']:.2e} | "
                     f"{r['steps']} | {r['substeps']} | {r['wall']:.3g} | "
                     f"{r['velocity']:.1f} / {r['position']:.1f} | {r['hits']} | "
                     f"{r['kinetic']:.2e} |")
    lines += ["", "Steps and substeps are counted from t = 0; wall s / sim s, sweeps and "
              "sweep-limit hits over the measured steps (the brute-force checks are not "
              "timed; the steps run one by one, not fused)."]
    for name, changes in variants_of(args):
        lines.append(f"- {name}: `{variant_text(changes)}`")
    return "\n".join(lines) + "\n"


#: --variants default: NAME=CHANGES (blank-separated field=value pairs: Tuning fields and
#: step_fraction)
#: the defaults, and the former ones (plain sweeps at 100 / 100, no substeps, full caps)
VARIANTS = ["defaults=", "former defaults=" + tuning_text(FORMER_DEFAULTS)]


def parse_variant(text: str) -> tuple:
    """("name", {field: value}) from "name=field=value field=value" (values through
    ast.literal_eval, else as strings): Tuning fields, and step_fraction (the
    Simulation's: simulation_options)."""
    import ast
    name, sep, rest = text.partition("=")
    if not sep or not name.strip():
        raise ValueError(f"a variant is NAME=FIELD=VALUE ..., got {text!r}")
    changes = {}
    for item in rest.split():
        field, eq, value = item.partition("=")
        if not eq:
            raise ValueError(f"variant {name!r}: {item!r} is not FIELD=VALUE")
        try:
            changes[field] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            changes[field] = value
    try:        # ValueError naming an unknown field or a bad value
        simulation_options(changes)
    except ValueError as exc:
        raise ValueError(f"variant {name!r}: {exc}") from None
    return name.strip(), changes


def variants_of(args) -> list:
    return [parse_variant(v) for v in args.variants]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=os.path.join("scenes", "pour.toml"))
    ap.add_argument("--start", type=float, default=0.0, help="measure from this time [s]")
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--every", type=int, default=5, help="check after every N-th step")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    ap.add_argument("--section", default="step-overlaps", help="docs/bench.md section")
    ap.add_argument("--variants", nargs="+", default=VARIANTS, metavar="NAME=CHANGES",
                    help='settings to compare, e.g. "fast=relaxation=1.8 substeps=True" '
                         '(default: the defaults and the former defaults)')
    args = ap.parse_args(argv)
    if not 0 <= args.start < args.duration or args.every < 1:
        ap.error("need 0 <= --start < --duration and --every >= 1")
    scene = ts.load_scene(os.path.join(ROOT, args.scene))
    try:
        variants = variants_of(args)
    except ValueError as err:
        ap.error(str(err))
    rows = {}
    for name, changes in variants:
        rows[name] = run(scene, args.start, args.duration, args.every, changes)
        print(name, rows[name], flush=True)
    publish(report(args, rows), args.section, args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
