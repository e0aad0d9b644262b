#!/usr/bin/env python3
"""Why the velocity sweeps converge slowly in a frictionless bed, flowing or settled:
the conditioning of the contacts its converged solve holds, at several times of the
pour.

scenes/pour.toml (2,000 frictionless spheres, e = 0.5) runs at the defaults on one
thread, f64, to each time of ``--at``; the velocity problem of the next step is
captured as the engine builds it (tools/solver_convergence.py ``capture``, the
parallel solver path: the same bits as the serial one) and solved to convergence in
numpy (APGD, ``--truth`` iterations from the warm start: solver_convergence.py
``apgd``). Reported per time:

- the rows, the rows the converged solution holds active (lambda > 0) and the
  spheres' degrees of freedom (3 N; frictionless contacts exert no torque);
- the rank of the active rows' Delassus matrix W_AA = J_A M^-1 J_A^T (its eigenvalues
  above 1e-10 of the largest; numpy's eigvalsh on the dense matrix): active rows
  beyond the rank are redundant, degrees of freedom beyond it are directions no
  active contact holds;
- W_AA's smallest nonzero eigenvalue over its largest (the inverse of its condition
  number on its range) and how many of its eigenvalues lie below 1e-3 of the
  largest: a first-order method such as projected Gauss-Seidel needs sweeps in
  proportion to some power of the condition number (Gauss-Seidel's rate on a
  symmetric positive definite system is set by the smallest eigenvalue);
- the converged solution's rms sphere speed [m/s] (how fast the bed moves in the
  exact solve of that step) against the rms speed after the engine's own sweeps and
  their rms error against the converged solution [m/s].

    python tools/bed_conditioning.py            # ~5 min
    python tools/bed_conditioning.py --write    # into docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from machine import cpu_name, publish  # noqa: E402  (tools/machine.py)
from bed_rest import rms_speed  # noqa: E402  (tools/bed_rest.py)
from solver_convergence import Problem, apgd, capture, delassus  # noqa: E402

#: eigenvalues of W_AA at most this share of the largest count as zero (its null space)
ZERO = 1e-10
#: eigenvalues below this share of the largest are reported as small
SMALL = 1e-3


def spectrum(eigenvalues) -> dict:
    """Rank (eigenvalues above ZERO of the largest), the largest eigenvalue, the smallest
    nonzero one over the largest, and how many nonzero ones lie below SMALL of the
    largest, of a symmetric positive semidefinite matrix's ``eigenvalues``."""
    ev = np.asarray(eigenvalues, dtype=np.float64)
    top = float(ev.max()) if ev.size else 0.0
    nonzero = ev[ev > ZERO * top] if top > 0 else ev[:0]
    return dict(rank=int(nonzero.size), largest=top,
                smallest=float(nonzero.min() / top) if nonzero.size else float("nan"),
                small=int((nonzero < SMALL * top).sum()))


def active_spectrum(prob: Problem, lam) -> dict:
    """spectrum() of the Delassus matrix of the rows ``lam`` holds active (> 0), with
    their count."""
    active = np.flatnonzero(lam > 0)
    W = delassus(prob)[active][:, active].toarray()
    out = spectrum(np.linalg.eigvalsh(W)) if active.size else spectrum([])
    out["active"] = int(active.size)
    return out


def measure(scene_path: str, at: float, truth: int) -> dict:
    """The figures of one time (module docstring)."""
    p = capture(scene_path, at, changes={})
    prob = Problem(p)
    lam, _ = apgd(prob, truth)
    exact = prob.velocities(lam)
    out = active_spectrum(prob, lam)
    out.update(at=at, rows=len(p["a"]), dofs=3 * len(p["v"]),
               residual=prob.residual(lam), exact_speed=rms_speed(exact),
               engine_speed=rms_speed(p["engine_v"]), sweeps=int(p["engine_sweeps"]),
               error=rms_speed(p["engine_v"] - exact))
    return out


def row_text(r: dict) -> str:
    """One table row of measure()'s figures."""
    return (f"| {r['at']:g} | {r['rows']} | {r['active']} | {r['rank']} | {r['dofs']} | "
            f"{r['active'] - r['rank']} | {r['dofs'] - r['rank']} | {r['smallest']:.1e} | "
            f"{r['small']} | {r['exact_speed']:.1e} | {r['sweeps']} | {r['engine_speed']:.1e} | "
            f"{r['error']:.1e} | {r['residual']:.1e} |")


def report(args, rows: list) -> str:
    at = " ".join(f"{t:g}" for t in args.at)
    command = "python tools/bed_conditioning.py"
    scene = os.path.relpath(args.scene, os.path.join(HERE, ".."))
    if scene != DEFAULT_SCENE:
        command += f" --scene {scene}"
    if list(args.at) != DEFAULT_AT:
        command += f" --at {at}"
    if args.truth != DEFAULT_TRUTH:
        command += f" --truth {args.truth}"
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread, f64: `{command}`",
             "",
             f"`{scene}` (frictionless) at the defaults, the velocity problem of the "
             "step after each time, solved to convergence (APGD, "
             f"{args.truth} iterations from the warm start); W_AA: the Delassus matrix of "
             "the rows active in that solution.",
             "",
             "| t [s] | rows | active rows | rank of W_AA | degrees of freedom (3 N) | "
             "redundant active rows | directions no active row holds | smallest nonzero "
             "eigenvalue of W_AA / largest | eigenvalues below 1e-3 of the largest | "
             "converged solve: rms speed [m/s] | engine's sweeps | after them: rms speed "
             "[m/s] | their rms error [m/s] | converged solve's residual [m/s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [row_text(r) for r in rows]
    return "\n".join(lines)


DEFAULT_AT = [1.0, 2.0, 6.0, 14.0]
DEFAULT_SCENE = os.path.join("scenes", "pour.toml")
DEFAULT_TRUTH = 5000


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(HERE, "..", DEFAULT_SCENE),
                    help="a frictionless scene (the captured problem has no friction rows)")
    ap.add_argument("--at", type=float, nargs="+", default=DEFAULT_AT,
                    help="times of the pour whose next step is captured [s]")
    ap.add_argument("--truth", type=int, default=DEFAULT_TRUTH,
                    help="APGD iterations for the converged solution")
    ap.add_argument("--write", action="store_true", help="write into docs/bench.md")
    args = ap.parse_args(argv)
    if not all(t > 0 for t in args.at):
        ap.error("--at takes times > 0")
    if args.truth < 1:
        ap.error("--truth must be at least 1")
    ts.runtime.ensure("cpu", "f64", threads=1)
    rows = []
    for t in args.at:
        rows.append(measure(args.scene, t, args.truth))
        print(row_text(rows[-1]), flush=True)
    publish(report(args, rows), "bed-conditioning", args.write)


if __name__ == "__main__":
    main()
