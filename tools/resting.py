#!/usr/bin/env python3
"""Resting contact report: a stacked column and a poured pile settle under gravity.

For each case it prints and writes to docs/resting.md (with date, machine and the
command): kinetic energy at the end and its peak, total energy change, the energy
budget (pair restitution, wall restitution, collapse rule, contact solver,
unaccounted), the contact solver's work (contacts and sweeps per step), the largest
overlap between any two spheres (brute force, relative to the contact distance) and
below the floor (relative to the radius), steps, sweeps per step, sweep-limit hits,
projected steps, and the wall time.

    python tools/resting.py            # column + the 2000-sphere scenes/pour.toml to 2 s, ~10 min
    python tools/resting.py --quick    # column + a 300-sphere pour
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.scenefile import scene_from_dict  # noqa: E402
from machine import cpu_name  # noqa: E402  (tools/machine.py)


def column(n=10, r=0.05, e=0.5):
    """n spheres stacked with gaps of 1 % of r in a 1 x 1 x 2 m box."""
    x = np.array([[0.5, 0.5, r + (2 * r + 0.001) * k] for k in range(n)])
    return ts.Scene.from_arrays(x, np.zeros((n, 3)), r, gravity=(0, 0, -9.81), restitution=e,
                                wall_restitution=e, box=((0, 0, 0), (1, 1, 2)),
                                name=f"column{n}")


def small_pour(count=300, e=0.5):
    return scene_from_dict({
        "name": f"pour{count}",
        "box": {"lo": [0.0, 0.0, 0.0], "hi": [0.2, 0.2, 0.6], "wall_restitution": e},
        "physics": {"gravity": [0.0, 0.0, -9.81], "restitution": e},
        "pour": [{"count": count, "lo": [0.02, 0.02, 0.2], "hi": [0.18, 0.18, 0.6],
                  "radius": 0.012, "density": 2500.0, "v": [0.0, 0.0, -1.0],
                  "v_spread": 0.05, "seed": 3}]}, source="tools/resting.py")


def overlaps(st):
    """(largest pair overlap / contact distance, largest floor penetration / radius)."""
    r = st.radius
    worst = 0.0
    for i0 in range(0, len(r), 512):       # blocks keep memory small for large N
        d = np.linalg.norm(st.x[i0:i0 + 512, None] - st.x[None], axis=-1)
        sig = r[i0:i0 + 512, None] + r[None]
        idx = np.arange(i0, min(i0 + 512, len(r)))
        d[np.arange(len(idx)), idx] = np.inf
        worst = max(worst, float((1 - d / sig).max()))
    floor = float(np.max((r - st.x[:, 2]) / r))
    return max(worst, 0.0), max(floor, 0.0)


def run(scene, t_end, samples=12):
    sim = ts.Simulation(scene, arch="cpu")
    kinetic, total = [], []
    t0 = time.perf_counter()
    for t in np.linspace(t_end / samples, t_end, samples):
        sim.advance_to(t)
        b = sim.energy_budget()
        kinetic.append(b["kinetic"])
        total.append(b["current"])
        print(f"  {scene.name} t = {t:.2f} s: kinetic {b['kinetic']:.3e} J, "
              f"total - initial {b['current'] - b['initial']:.4g} J", flush=True)
    wall = time.perf_counter() - t0
    st = sim.state()
    pair, floor = overlaps(st)
    s = sim.stats
    b = sim.energy_budget()
    return dict(name=scene.name, n=scene.n, t=t_end, wall=wall, ke_end=kinetic[-1],
                ke_peak=max(kinetic), e0=b["initial"], e_max=max(total), e_end=b["current"],
                budget=b, pair=pair, floor=floor, steps=s["steps"],
                sweeps=s["sweeps"] / max(s["steps"], 1), limit=s["sweep_limit_hits"],
                projected=s["projected_steps"], impact_speed=sim.rest_speed,
                contacts=s["contacts"] / max(s["contact_steps"], 1),
                iterations=s["contact_iterations"] / max(s["contact_steps"], 1),
                residual=s["contact_residual"],
                mgr=float(scene.mass.sum() * np.linalg.norm(scene.gravity) * scene.radius.max()))


def markdown(rows, command, total):
    out = ["# Resting contact\n",
           f"Generated {datetime.date.today().isoformat()} on {cpu_name()} (CPU backend, f64) "
           f"by `{command}` in {total:.0f} s. Method: docs/algorithm.md, "
           f"\"Persistent contacts: the contact solver\".\n",
           "| case | N | t (s) | KE end / KE peak | KE end / (M g r) | max(E) − E0 (J) | E0 − E end (J) | "
           "max overlap / σ | floor / r | steps | sweeps/step | limit hits | projected steps "
           "| wall s |",
           "|:--|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for r in rows:
        out.append(f"| {r['name']} | {r['n']} | {r['t']:g} | {(r['ke_end'] / r['ke_peak'] if r['ke_peak'] > 0 else 0.0):.1e} | "
                   f"{r['ke_end'] / r['mgr']:.1e} | "
                   f"{r['e_max'] - r['e0']:.2e} | {r['e0'] - r['e_end']:.4g} | {r['pair']:.1e} | "
                   f"{r['floor']:.1e} | {r['steps']} | {r['sweeps']:.1f} | {r['limit']} | "
                   f"{r['projected']} | {r['wall']:.0f} |")
    out.append("\nEnergy budget at the end (J): lost to pair restitution, wall restitution, "
               "the collapse rule, the contact solver, and unaccounted (initial − current − "
               "booked); the impact speed (approaches slower than it at touching pairs and "
               "walls are persistent contacts) and the contact solver's rows and velocity "
               "sweeps per step it ran, and its largest residual:\n")
    out.append("| case | impact speed (m/s) | pairs | walls | collapse | contacts | unaccounted "
               "| contacts/step | sweeps/step | residual (m/s) |")
    out.append("|:--|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        b = r["budget"]
        out.append(f"| {r['name']} | {r['impact_speed']:.3g} | {b['pair_restitution']:.4g} | "
                   f"{b['wall_restitution']:.4g} | {b['collapse']:.4g} | {b['contacts']:.4g} | "
                   f"{b['unaccounted']:.3g} | {r['contacts']:.1f} | {r['iterations']:.1f} | "
                   f"{r['residual']:.1e} |")
    out.append("\nKE peak is the largest of the sampled kinetic energies (12 samples; the "
               "column starts at rest, so its ratio says nothing: see KE end / (M g r), the "
               "kinetic energy left against that of the whole mass falling one radius). "
               "`unaccounted` is round-off, or the energy of wall rests and of overlaps the "
               "projection moved (`Simulation.energy_budget`; the contact solver books the "
               "potential energy of its own moves); `max(E) − E0` ≤ 0 means the total "
               "energy never rose above its start at the samples.\n")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a 300-sphere pour instead of 2000")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "resting.md"))
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    command = "python tools/resting.py" + (" --quick" if args.quick else "")
    t0 = time.perf_counter()
    rows = [run(column(), 2.0)]
    if args.quick:
        rows.append(run(small_pour(), 1.5))
    else:
        rows.append(run(ts.load_scene(os.path.join(ROOT, "scenes", "pour.toml")), 2.0))
    text = markdown(rows, command, time.perf_counter() - t0)
    print(text)
    if not args.no_write:
        with open(args.out, "w") as fh:
            fh.write(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
