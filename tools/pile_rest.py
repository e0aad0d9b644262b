#!/usr/bin/env python3
"""Does a box-filling pile come to rest and hold without drift, with and without
friction? A pile at rest keeps every speed below 1e-6 m/s and does not drift over
10 s; this measures what a frictionless pile does, in taichi_spheres and in LAMMPS.

The pile: taichi_spheres.builders.box_pile, n_side x n_side x 3 spheres of r = 10 mm
on a jittered lattice dropped into a box they fill about 1.6 layers deep (e = 0.5
between spheres and on the walls; the suite's pile is its seed 3); ``--seeds`` fills.
Runs, 1 thread, f64:

- taichi_spheres at the defaults, frictionless and with friction 0.5 and rolling
  friction 0.1 (the suite's test_box_filling_pile_settles_and_holds), and
  frictionless with 1,000 velocity and 1,000 position sweeps at most per step (a solve
  far closer to the converged one; tools/bed_rest.py's second run);
- LAMMPS GRANULAR, frictionless Hertz as tools/peer_lammps.py (E = 5e9 Pa, nu = 0.3,
  dt = 5e-6 s), from the same spheres (~3 min a fill on one core; ``--no-lammps``).

Sampled at ``--settle`` s, every second after and at settle + 10 s. Reported per run:
kinetic energy / initial energy at both ends of the hold, how many spheres are faster
than 1e-6 m/s at its end and how many of them *slide freely*: their velocity is the
same at the last two samples (within 1e-9 m/s, one second apart: no force acts along
it; frictionless contacts push only along their normals, so a sphere on the floor or
against a wall keeps any velocity along it), the largest displacement over the hold /
diameter of all spheres and of the others, the largest overlap at the samples /
diameter (pairs and box walls, from the positions), and for taichi_spheres the
sweep-limit hits in the hold and the wall time of the whole run.

    python tools/pile_rest.py              # ~15 min with LAMMPS
    python tools/pile_rest.py --write      # into docs/bench.md, section pile-rest
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.builders import PILE_RADIUS as RADIUS, box_pile  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, publish, untimed_pass  # noqa: E402  (tools/machine.py)
import peer_lammps  # noqa: E402
import bed_rest  # noqa: E402  (tools/bed_rest.py)
from bed_rest import DT, POISSON, YOUNG  # noqa: E402  (LAMMPS's model and step)

#: the speed a pile at rest stays below [m/s]
REST_SPEED = 1e-6
#: a sphere whose velocity changed by less than this over the last second slides freely
FREE = 1e-9
#: how long a pile at rest holds without drift [s]
HOLD = 10.0


def sample_times(settle: float) -> list:
    """settle, each whole second of the hold after it, settle + HOLD [s]."""
    return [settle + k for k in range(int(HOLD) + 1)]


def hold_report(samples: list, scene) -> dict:
    """From (x, v) samples (N, 3) [m, m/s] at sample_times: speeds above REST_SPEED at
    the end, those of them sliding freely (velocity within FREE of the sample before),
    the largest speed [m/s], the largest displacement over the hold / diameter of all
    spheres and of the others, and the largest pair or box-wall overlap / diameter at
    the samples (peer_lammps.largest_overlaps)."""
    (x0, _), (_, v_prev), (x1, v1) = samples[0], samples[-2], samples[-1]
    speed = np.linalg.norm(v1, axis=1)
    moving = speed > REST_SPEED
    free = moving & (np.abs(v1 - v_prev).max(axis=1) <= FREE)
    moved = np.linalg.norm(x1 - x0, axis=1) / (2 * RADIUS)
    others = moved[~free]
    return dict(moving=int(moving.sum()), free=int(free.sum()), largest_speed=float(speed.max()),
                drift=float(moved.max()), drift_others=float(others.max()) if others.size else 0.0,
                overlap=max(max(peer_lammps.largest_overlaps(
                    x, np.full(len(x), RADIUS), scene.box_lo, scene.box_hi)) for x, _ in samples))


def run_taichi(scene, settle: float, tuning: dict) -> dict:
    """taichi_spheres under ``tuning`` (Tuning.with_ changes; 1 thread, f64):
    hold_report, kinetic energy (spin included) / initial energy at both ends of the
    hold, sweep-limit hits in the hold and wall s of the whole run (its first step's
    compile excluded)."""
    sim = ts.Simulation(scene, threads=1, tuning=Tuning().with_(**tuning))
    untimed_pass(sim, lambda s: s.advance(s.max_step()))
    e0, samples, kinetic = sim.initial_energy, [], []
    t0 = time.perf_counter()
    sim.advance_to(settle)
    hits = sim.stats["sweep_limit_hits"]
    for t in sample_times(settle):
        sim.advance_to(t)
        st = sim.state()
        samples.append((st.x.copy(), st.v.copy()))
        kinetic.append((ts.observe.kinetic_energy(st) + ts.observe.rotational_energy(st)) / e0)
    out = hold_report(samples, scene)
    out.update(kinetic=(kinetic[0], kinetic[-1]), hits=sim.stats["sweep_limit_hits"] - hits,
               wall=time.perf_counter() - t0)
    return out


def run_lammps(scene, settle: float) -> dict:
    """LAMMPS (frictionless Hertz, bed_rest.lammps_samples): hold_report and kinetic
    energy / initial energy at both ends of the hold (no wall time)."""
    with contextlib.closing(bed_rest.lammps_samples(scene, sample_times(settle))) as samples:
        x, v, m, _ = next(samples)
        e0 = peer_lammps.energies(x, v, m, scene.gravity)[1]
        held, kinetic = [], []
        for x, v, m, _ in samples:
            held.append((x, v))
            kinetic.append(peer_lammps.energies(x, v, m, scene.gravity)[0] / e0)
    out = hold_report(held, scene)
    out.update(kinetic=(kinetic[0], kinetic[-1]), hits=None, wall=None)
    return out


#: the runs: label -> (code, friction mu, rolling friction mu_r, Tuning.with_ changes)
RUNS = {
    "taichi_spheres, frictionless": ("taichi", 0.0, 0.0, {}),
    "taichi_spheres, frictionless, 1000 / 1000 sweeps":
        ("taichi", 0.0, 0.0, dict(contact_iterations=1000, position_iterations=1000)),
    "LAMMPS, frictionless": ("lammps", 0.0, 0.0, None),
    "taichi_spheres, friction 0.5, rolling 0.1": ("taichi", 0.5, 0.1, {}),
}


def measure(args) -> list:
    """(label, seed, result) of every run (RUNS, without LAMMPS's with --no-lammps)."""
    out = []
    for label, (code, mu, mu_r, tuning) in RUNS.items():
        if code == "lammps" and args.no_lammps:
            continue
        for seed in args.seeds:
            scene = box_pile(args.n_side, friction=mu, rolling_friction=mu_r, seed=seed)
            result = (run_taichi(scene, args.settle, tuning) if code == "taichi"
                      else run_lammps(scene, args.settle))
            print(f"{label}, seed {seed}: {result}", flush=True)
            out.append((label, seed, result))
    return out


def row(label, seed, r) -> str:
    """One table row."""
    hits = "-" if r["hits"] is None else str(r["hits"])
    wall = "-" if r["wall"] is None else f"{r['wall']:.1f}"
    return (f"| {label} | {seed} | {r['kinetic'][0]:.1e} | {r['kinetic'][1]:.1e} | "
            f"{r['moving']} | {r['free']} | {r['largest_speed']:.1e} | {r['drift']:.1e} | "
            f"{r['drift_others']:.1e} | {r['overlap']:.1e} | {hits} | {wall} |")


def report(args, rows, argv) -> str:
    """The markdown section; ``argv``: the command line's options."""
    cmd = " ".join(["python tools/pile_rest.py"] + [a for a in argv if a != "--write"])
    n = 3 * args.n_side ** 2
    end = args.settle + HOLD
    lines = [
        f"Measured {datetime.date.today().isoformat()} on {cpu_name()}, 1 thread each: `{cmd}`",
        "",
        f"{n} spheres of d = {2 * RADIUS * 1e3:g} mm dropped into a box "
        f"{box_pile(args.n_side).box_hi[0] * 1e3:g} mm wide (e = 0.5), held from "
        f"{args.settle:g} to {end:g} s; taichi_spheres at the defaults unless a row says "
        f"otherwise (f64); LAMMPS "
        f"frictionless Hertz, E = {YOUNG:g} Pa, nu = {POISSON}, dt = {DT:g} s. *Moving*: "
        f"faster than {REST_SPEED:g} m/s at {end:g} s; *sliding freely*: of those, the "
        f"velocity unchanged over the last second (within {FREE:g} m/s); drift: the largest "
        f"displacement over the hold / d; overlap: the largest at the samples (every second) / d; "
        "wall s: the whole run.",
        "",
        f"| run | seed | K / E0 at {args.settle:g} s | K / E0 at {end:g} s | moving | sliding "
        "freely | largest speed [m/s] | drift / d | drift of the others / d | overlap / d | "
        "sweep-limit hits in the hold | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [row(label, seed, r) for label, seed, r in rows]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--n-side", type=int, default=10, help="spheres per lattice row")
    ap.add_argument("--settle", type=float, default=6.0, help="start of the hold [s]")
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = ap.parse_args(argv)
    if args.n_side < 2:
        ap.error(f"--n-side must be >= 2, got {args.n_side}")
    if not (math.isfinite(args.settle) and args.settle > 0):
        ap.error(f"--settle must be a finite time > 0 s, got {args.settle}")
    if min(args.seeds) < 0:
        ap.error(f"--seeds must be >= 0, got {min(args.seeds)}")
    if not args.no_lammps:
        peer_lammps.ensure_lib_path()          # (re-executes once with libmpi's path)
    publish(report(args, measure(args), argv), "pile-rest", args.write)


if __name__ == "__main__":
    main()
