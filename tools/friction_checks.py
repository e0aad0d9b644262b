#!/usr/bin/env python3
"""Friction and spin against closed forms: sliding to rolling on a floor, a sphere on an
incline in both regimes, Walton's oblique impacts between two spheres and on a wall.

Reported per case: the measured value, the closed form and the relative error, in f64
and f32 (the same cases as tests/test_friction.py, which asserts them); the cases on a
support at the default over-relaxation (Rules.relaxation 1.8: within the solver's
tolerance) and with plain sweeps (1.0: round-off).

    python tools/friction_checks.py            # ~1 min on 2 cores
    python tools/friction_checks.py --write    # the 'closed forms' section of docs/granular.md
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

import taichi_spheres as ts  # noqa: E402
from taichi_spheres import observe  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from taichi_spheres.reference import walton_impact  # noqa: E402
from machine import cpu_name, write_section  # noqa: E402  (tools/machine.py)

G = 9.81
DOCS = os.path.join(os.path.dirname(__file__), "..", "docs")


#: Rules.relaxation of the cases on a support: the default, and plain sweeps
RELAXATIONS = (Tuning().physics.relaxation, 1.0)


def sliding(precision, relaxation) -> tuple:
    """(final speed, 5/7 v0) of a sphere launched sliding at v0 = 1 m/s, mu = 0.3."""
    r, mu = 0.05, 0.3
    sc = ts.Scene.from_arrays([[0.2, 0.5, r]], [[1.0, 0, 0]], r, box=((0, 0, 0), (2, 1, 1)),
                              restitution=0.5, wall_restitution=0.5, friction=mu)
    sim = ts.Simulation(sc, precision=precision, tuning=Tuning().with_(relaxation=relaxation))
    sim.advance(0.5)
    return sim.state().v[0, 0], 5 / 7


def incline(precision, degrees, relaxation) -> tuple:
    """(speed after 0.1 s, the closed form) on a plane tilted by ``degrees``, mu = 0.3."""
    r, mu, th = 0.02, 0.3, math.radians(degrees)
    n = np.array([-math.sin(th), 0.0, math.cos(th)])
    p0 = np.array([0.5, 0.5, 0.5])
    sc = ts.Scene.from_arrays([p0 + r * n], [[0, 0, 0]], r, restitution=0.5,
                              wall_restitution=0.5, friction=mu, geometry=[ts.Plane(p0, n)])
    sim = ts.Simulation(sc, precision=precision, tuning=Tuning().with_(relaxation=relaxation))
    sim.advance(0.1)
    a = 5 / 7 * G * math.sin(th) if math.tan(th) <= 3.5 * mu else \
        G * (math.sin(th) - mu * math.cos(th))
    return sim.state().v[0] @ np.array([-math.cos(th), 0.0, -math.sin(th)]), a * 0.1


def pair_impact(beta0, w1) -> tuple:
    """(largest velocity error / speed, angular momentum change / ‖L‖) of an oblique
    impact of glass-like spheres (e 0.97, mu 0.092) against Walton's closed form."""
    e, mu = 0.97, 0.092
    r = np.array([0.01, 0.015])
    n = np.array([-0.8, -0.36, 0.48]) / np.linalg.norm([-0.8, -0.36, 0.48])
    x = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]])
    x[1] -= n * r.sum()
    v = np.array([[0.6, 0.2, -0.3], [-0.4, 0.1, 0.05]])
    w = np.array([w1, (20.0, 0.0, 30.0)], dtype=float)
    m = 1000 * 4 / 3 * np.pi * r ** 3
    sc = ts.Scene.from_arrays(x, v, r, gravity=(0, 0, 0), restitution=e, friction=mu,
                              tangential_restitution=beta0, omega=w)
    sim = ts.Simulation(sc)
    before = sim.state()
    sim.advance(1e-3)
    st = sim.state()
    want = walton_impact(v[0], v[1], w[0], w[1], r[0], r[1], m[0], m[1], n, e, mu, beta0)
    err = max(np.abs(st.v[0] - want[0]).max(), np.abs(st.v[1] - want[1]).max(),
              np.abs(st.omega[0] - want[2]).max() * r[0],
              np.abs(st.omega[1] - want[3]).max() * r[1]) / np.abs(v).max()
    l0, l1 = observe.angular_momentum(before), observe.angular_momentum(st)
    return err, np.abs(l1 - l0).max() / np.abs(l0).max()


def rows() -> list:
    """(case, precision, measured, expected or note, relative error) of every check."""
    out = []
    for omega in RELAXATIONS:
        for p in ("f64", "f32"):
            got, want = sliding(p, omega)
            out.append((f"sliding to rolling: final speed / v0, relaxation {omega:g}", p, got,
                        want, abs(got / want - 1)))
            for deg, regime in ((20.0, "rolls"), (60.0, "slides")):
                got, want = incline(p, deg, omega)
                out.append((f"incline {deg:g} deg ({regime}): speed at 0.1 s [m/s], "
                            f"relaxation {omega:g}", p, got, want, abs(got / want - 1)))
    for beta0, w1, label in ((0.35, (0, 0, 0), "sticking"), (0.35, (0, 400, -100), "sliding"),
                             (-1.0, (0, 0, 0), "beta0 = -1")):
        err, dl = pair_impact(beta0, w1)
        out.append((f"pair impact, {label}: velocities and spins vs Walton", "f64", err,
                    "error / speed", err))
        out.append((f"pair impact, {label}: angular momentum change / ‖L‖", "f64", dl,
                    "0", dl))
    return out


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", action="store_true")
    a = ap.parse_args(argv)
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}: "
             "`python tools/friction_checks.py`", "",
             "| case | precision | measured | closed form | relative error |",
             "|---|---|---|---|---|"]
    for case, p, got, want, err in rows():
        want_text = f"{want:.10g}" if isinstance(want, float) else want
        lines.append(f"| {case} | {p} | {got:.10g} | {want_text} | {err:.1e} |")
    text = "\n".join(lines)
    print(text)
    if a.write:
        write_section(os.path.join(DOCS, "granular.md"), "closed-forms", text)


if __name__ == "__main__":
    main()
