#!/usr/bin/env python3
"""Kinetic energy of the pour's bed phase against time, for solves of increasing
accuracy: is the energy left at t = 2 s the solver's error or the bed's own motion?

scenes/pour.toml (2,000 frictionless spheres, e = 0.5) runs to t1 = 1 s at the
defaults (1 thread); from that state the bed phase [1, 2] s runs again under each
setting (velocity / position sweep caps, Rules.relaxation), printing the kinetic
energy at 1.25, 1.5, 1.75 and 2 s, with the velocity sweeps per step and the wall
seconds per simulated second. The sweeps stop early only at the tolerance, so more
sweeps means a solve closer to the exact one. LAMMPS's kinetic energy at 1 and 2 s of
the same pour (docs/peer_lammps_pour_lammps.json, tools/peer_lammps.py) is quoted.

    python tools/bed_energy.py --write           # ~2 min on 1 core
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)

TIMES = (1.25, 1.5, 1.75, 2.0)
#: (velocity sweeps, position sweeps, relaxation) of each run, without substeps; the
#: first is the contact solver's former default
SETTINGS = [(100, 100, 1.0), (300, 300, 1.0), (1000, 1000, 1.0), (100, 100, 1.8),
            (300, 300, 1.8)]
LAMMPS_JSON = os.path.join(ROOT, "docs", "peer_lammps_pour_lammps.json")


def bed_phase(scene, at_t1, vel: int, pos: int, omega: float) -> dict:
    """Kinetic energy at TIMES [J], velocity sweeps per step, wall s per simulated s."""
    tuning = Tuning().with_(contact_iterations=vel, position_iterations=pos, relaxation=omega,
                            substeps=False, step_scaled_sweeps=False)
    sim = ts.Simulation(scene, threads=1, tuning=tuning)
    sim.restore(at_t1)
    sim.step(sim.max_step())         # compiles this setting's kernels (not timed)
    sim.restore(at_t1)
    sweeps, steps = sim.stats["contact_iterations"], sim.stats["contact_steps"]
    t0, start, ke = time.perf_counter(), sim.time, []
    for t in TIMES:
        sim.advance_to(t)
        ke.append(ts.observe.kinetic_energy(sim.state()))
    wall = (time.perf_counter() - t0) / (sim.time - start)
    per_step = (sim.stats["contact_iterations"] - sweeps) / max(
        sim.stats["contact_steps"] - steps, 1)
    return dict(ke=ke, sweeps=per_step, wall=wall)


def lammps_energy() -> str:
    """LAMMPS's kinetic energy at the phase ends of the stored pour run, as text."""
    with open(LAMMPS_JSON) as fh:
        run = json.load(fh)
    e0 = run["result"]["e0"]
    return ", ".join(f"{r['kinetic']:.2e} J ({r['kinetic'] / e0:.1e} of the initial energy) "
                     f"at {r['t']:g} s" for r in run["result"]["rows"])


def report(scene_path, e0, rows) -> str:
    """The markdown section."""
    head = " | ".join(f"KE at {t:g} s [J]" for t in TIMES)
    lines = [f"{datetime.date.today()}, {cpu_name()}, 1 thread, f64: "
             "`python tools/bed_energy.py --write`.", "",
             f"`{scene_path}` from its state at t = 1 s (defaults up to there), the bed phase "
             f"again with each solve; initial energy {e0:.1f} J.", "",
             f"| velocity / position sweeps at most | relaxation | {head} | KE at 2 s / initial "
             "energy | velocity sweeps per step | wall s per simulated s |",
             "|---|---|" + "---|" * len(TIMES) + "---|---|---|"]
    for (vel, pos, omega), r in rows.items():
        kes = " | ".join(f"{k:.2e}" for k in r["ke"])
        lines.append(f"| {vel} / {pos} | {omega:g} | {kes} | {r['ke'][-1] / e0:.1e} | "
                     f"{r['sweeps']:.0f} | {r['wall']:.2f} |")
    lines += ["", f"LAMMPS (Hertz, same pour, {LAMMPS_JSON.split(os.sep)[-1]}): "
              f"{lammps_energy()}."]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default=os.path.join("scenes", "pour.toml"))
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    args = ap.parse_args(argv)
    scene = ts.load_scene(os.path.join(ROOT, args.scene))
    sim = ts.Simulation(scene, threads=1)
    sim.advance_to(1.0)
    at_t1, e0 = sim.checkpoint(), sim.initial_energy
    rows = {}
    for setting in SETTINGS:
        rows[setting] = bed_phase(scene, at_t1, *setting)
        print(setting, rows[setting], flush=True)
    publish(report(args.scene, e0, rows), "bed-energy", args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
