#!/usr/bin/env python3
"""How much of a contact solve's work changes nothing, and what skipping it would save:
the velocity sweeps of sampled steps of the pour, replayed row update by row update as
the engine runs them at its defaults.

For each time in ``--at`` (default: six times through the pour's fall and two in its
bed), scenes/pour.toml is run there (1 thread) and the velocity problem of the next
step is captured as the engine builds it (tools/solver_convergence.py ``capture``, at
the defaults: over-relaxed sweeps, substeps). Its velocity solve is replayed in numpy:
over-relaxed sweeps, plain ones at the end of the cap, the same stopping rule
(contacts/pgs.py ``iterate_serially``), checked against the engine (largest velocity
difference, sweeps). Three replays:

- as the engine runs it, counting the row updates that are exactly skippable: the row
  had no impulse, its last update changed nothing, and neither of its spheres'
  velocities has changed since, so the update would compute the same zero again (for
  any relaxation factor). Skipping exactly these keeps the bits;
- skipping them (an active set kept between sweeps): the share skipped, and the
  check that the velocities stay the engine's;
- skipping by threshold: a row whose last update changed at most ``--threshold`` of
  the step's tolerance (|Δλ| / m_eff, the solver's residual), while neither sphere was
  changed by more than that since, is skipped, and changes below it mark no sphere.
  This skips more at the cost of the bits: reported with its sweeps and how far its
  velocities end from the engine's.

Reported per captured step: rows, the step, the sweeps, and the share of the row
updates each scheme skips; overall, the shares weighted by the updates of each step.
A skip costs the engine a few loads and stores per row update that is not skipped, so
a scheme pays only where it skips a large share.

    python tools/row_activity.py                 # ~3 min
    python tools/row_activity.py --write         # the 'row-activity' section of docs/bench.md
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Rules  # noqa: E402
from taichi_spheres.contacts.pgs import next_sweep, plain_sweep  # noqa: E402
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)
from solver_convergence import Problem, capture, update_row  # noqa: E402

#: --at default: through the fall (impacts on a growing bed) and in the bed
TIMES = [0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.5]


def replay(prob: Problem, rules: Rules, tol: float, skip: str = "none",
           threshold: float = 0.0) -> dict:
    """The engine's velocity solve of the captured problem in numpy (Rules: the
    capture's; tol: its velocity tolerance [m/s]). ``skip``: "none"
    (count the exactly skippable updates, skip nothing), "exact" (skip them) or
    "threshold" (skip rows whose last change was at most threshold x tol while no
    larger change touched their spheres). Returns the updates run, the skippable or
    skipped ones, the sweeps and the velocities at the end."""
    p = prob.p
    a, b, n, meff, tgt = prob.lists
    im = prob.im
    order = p["order"].tolist()
    lam, vl = p["lam"].tolist(), p["v"].tolist()
    small = threshold * tol if skip == "threshold" else 0.0
    stamp = [-1] * len(vl)          # update count at a sphere's last (large) change
    seen = [-2] * len(lam)          # update count at a row's last idle update
    clock, updates, skipped = 0, 0, 0
    cap = rules.contact_iterations
    it, relaxed, done = 0, int(rules.relaxation != 1), 0
    while done == 0:        # the engine's rule (taichi_spheres/contacts/pgs.py)
        plain = plain_sweep(it, relaxed, cap, rules.plain_sweeps)
        omega = 1.0 if plain else rules.relaxation
        residual = 0.0
        for s in order:
            ai, bi = a[s], b[s]
            clock += 1
            updates += 1
            if seen[s] > stamp[ai] and (bi < 0 or seen[s] > stamp[bi]):
                skipped += 1
                if skip != "none":
                    continue
            change = abs(update_row(s, ai, bi, n[s], meff[s], tgt[s], omega, lam, vl,
                                    im)) / meff[s]
            residual = max(residual, change)
            if change > small:
                stamp[ai] = clock
                if bi >= 0:
                    stamp[bi] = clock
            idle = change <= small if skip == "threshold" else (change == 0.0 and lam[s] == 0.0)
            seen[s] = clock if idle else -2
        it, relaxed, done = next_sweep(it, relaxed, plain, cap, int(not residual > tol))
    return dict(updates=updates, skipped=skipped, sweeps=it, v=np.array(vl))


def measure(scene: str, at: float, threshold: float) -> dict:
    """Capture the step after ``at`` s at the defaults and replay its velocity solve
    three ways (module docstring)."""
    p = capture(scene, at, changes={})
    # the defaults the capture ran with, at the cap it was given
    prob, rules = Problem(p), dataclasses.replace(Rules(), contact_iterations=p["sweeps"],
                                                plain_sweeps=p["plain"])
    plain = replay(prob, rules, p["tol"])
    exact = replay(prob, rules, p["tol"], "exact")
    rough = replay(prob, rules, p["tol"], "threshold", threshold)
    return dict(rows=len(p["a"]), h=p["h"], engine_sweeps=p["engine_sweeps"],
                sweeps=plain["sweeps"], updates=plain["updates"],
                skippable=plain["skipped"] / plain["updates"],
                check=float(np.abs(plain["v"] - p["engine_v"]).max()),
                exact=exact["skipped"] / exact["updates"],
                exact_check=float(np.abs(exact["v"] - p["engine_v"]).max()),
                rough=rough["skipped"] / rough["updates"], rough_sweeps=rough["sweeps"],
                rough_error=float(np.abs(rough["v"] - p["engine_v"]).max()))


def report(args, rows) -> str:
    command = "python tools/row_activity.py" + \
        (" --at " + " ".join(f"{t:g}" for t in args.at) if args.at != TIMES else "") + \
        (f" --threshold {args.threshold:g}" if args.threshold != 0.01 else "")
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}: `{command}`", "",
             "`scenes/pour.toml` at the defaults: the velocity solve of the step after each "
             "time, replayed in numpy (\"replay − engine\": the largest velocity difference "
             "from the engine's solve, 0 where the bits are the same). Shares of the row "
             f"updates skipped; threshold: {args.threshold:g} of the step's tolerance.", "",
             "| step after | rows | step [ms] | sweeps (engine) | replay − engine [m/s] | "
             "exactly skippable | skipped exactly (replay − engine) | skipped by threshold "
             "(sweeps; replay − engine [m/s]) |",
             "|---|---|---|---|---|---|---|---|"]
    for at, r in rows:
        lines.append(f"| {at:g} s | {r['rows']} | {r['h'] * 1e3:.2f} | {r['sweeps']} "
                     f"({r['engine_sweeps']}) | {r['check']:.1e} | {r['skippable']:.2f} | "
                     f"{r['exact']:.2f} ({r['exact_check']:.1e}) | {r['rough']:.2f} "
                     f"({r['rough_sweeps']}; {r['rough_error']:.1e}) |")
    total = sum(r["updates"] for _, r in rows)
    weighted = {k: sum(r[k] * r["updates"] for _, r in rows) / total
                for k in ("exact", "rough")}
    lines += ["", f"Weighted by each step's row updates: **{weighted['exact']:.2f}** of them "
              f"skipped exactly, **{weighted['rough']:.2f}** by threshold."]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(HERE, "..", "scenes", "pour.toml"))
    ap.add_argument("--at", type=float, nargs="+", default=TIMES)
    ap.add_argument("--threshold", type=float, default=0.01,
                    help="threshold skip: changes up to this fraction of the tolerance")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    if any(t < 0 for t in args.at):
        ap.error("--at times must be >= 0")
    if not 0 <= args.threshold < 1:
        ap.error("--threshold must be in [0, 1)")
    if ts.load_scene(args.scene).frictional:
        ap.error("the replay has no friction rows: give a frictionless scene")
    ts.runtime.ensure("cpu", "f64", threads=1)
    rows = [(t, measure(args.scene, t, args.threshold)) for t in args.at]
    publish(report(args, rows), "row-activity", args.write)


if __name__ == "__main__":
    main()
