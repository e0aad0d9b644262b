#!/usr/bin/env python3
"""LAMMPS's Hertz–Mindlin contact read as Walton's impact parameters: the normal
restitution e and the tangential restitution beta of one sphere's oblique impact on a
wall, against the impact angle.

taichi_spheres collides spheres with Walton's model (docs/algorithm.md): e, Coulomb
friction mu, and for sticking impacts a tangential restitution beta0 (-1 <= beta0 <= 1;
the default beta0 = -1 caps a sticking impact at beta = 0: the contact point stops).
LAMMPS GRANULAR, as tools/lammps_silo.py sets it up for the silo and heap comparisons
(Hertz from E and nu, damping from the restitution, Mindlin friction with its
tangential spring, optional sds rolling and twisting resistance), has no beta0: its
tangential spring stores energy during a sticking impact and returns part of it, so its
impacts have a beta of their own. This tool measures it, to compare like with like.

One sphere (--radius, --density) meets a wall/gran plane (the same model text as the
comparisons' walls; gravity off) with normal speed --vn and tangential contact speed
u_t = psi mu (1 + e) v_n, no spin, for each psi in --psi. After it leaves the wall:
e = -v_n' / v_n and beta = -u_t' / u_t (u_t the velocity of the contact point, v_t -
r w x n). Walton's model gives beta = beta0 while psi <= 7 / (2 (1 + beta0))
(sticking) and beta = -1 + 7 / (2 psi) beyond (sliding); the report gives LAMMPS's beta
beside Walton's with beta0 = 0, the law of taichi_spheres's default.

    python tools/lammps_walton.py                  # mu 0.3 0.6, mu_r 0 0.1 (~10 s)
    python tools/lammps_walton.py --write          # the 'lammps-walton' section of docs/granular.md
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

import lammps_silo  # noqa: E402  (tools/lammps_silo.py)
from machine import cpu_name, write_section  # noqa: E402  (tools/machine.py)

DOCS = os.path.join(HERE, "..", "docs")


def wall_impact(lammps, a, mu, mu_r, psi) -> dict:
    """e, beta and psi of one impact of a sphere on the plane z = 0 (module docstring),
    friction mu, rolling friction mu_r; psi sets the tangential contact speed."""
    r = a.radius
    m = a.density * 4 / 3 * math.pi * r ** 3
    ut = psi * mu * (1 + a.e) * a.vn
    steps = int(math.ceil(20 * r / a.vn / a.dt))          # in, out and 18 radii away
    reach = 0.1 + 2 * ut * steps * a.dt                   # the box holds its whole path
    top = 0.1 + 2 * r + 2 * a.vn * steps * a.dt
    lmp = lammps_silo.create_system(lammps, np.array([[0.0, 0.0, r * (1 + 1e-6)]]),
                                    np.array([r]), np.array([m]), (-reach, -0.1, 0.0),
                                    (reach, 0.1, top), a.dt, 1)
    lmp.command("unfix grav")
    roll = lammps_silo.rolling_defaults(np.array([r]), np.array([m]), a.dt)
    model = lammps_silo.contact_model(a.young, a.poisson, a.e, mu, mu_r, roll, r)
    lmp.command(f"fix floor all wall/gran granular {model} zplane 0.0 NULL")
    lmp.numpy.extract_atom("v")[0] = [ut, 0.0, -a.vn]
    lmp.command(f"run {steps} post no")
    z = float(lmp.numpy.extract_atom("x")[0][2])
    v = np.array(lmp.numpy.extract_atom("v")[0], dtype=float)
    w = np.array(lmp.numpy.extract_atom("omega")[0], dtype=float)
    lmp.close()
    if z <= r:
        raise RuntimeError(f"psi {psi}: the sphere is still on the wall after {steps} steps")
    ut_after = v[0] - r * w[1]               # contact point -r z: v + w x (-r z), along x
    return dict(psi=psi, e=v[2] / a.vn, beta=-ut_after / ut)


def walton_beta(psi, beta0=0.0) -> float:
    """Walton's beta: min(beta0, -1 + 7 / (2 psi)) (sticking, then sliding); beta0 = 0
    is taichi_spheres's default (tangential_restitution -1 caps a sticking impact at
    0)."""
    return min(beta0, -1 + 3.5 / psi)


def report(rows, argv, a) -> str:
    """Markdown table of the impacts (docs/granular.md section 'lammps-walton')."""
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}: "
             f"`{' '.join(['python tools/lammps_walton.py'] + list(argv))}`", "",
             f"One sphere (r = {1e3 * a.radius:g} mm, {a.density:g} kg/m^3) meets a LAMMPS "
             f"wall/gran plane at v_n = {a.vn:g} m/s (E = {a.young:g} Pa, nu = {a.poisson:g}, "
             f"e = {a.e:g}, Mindlin friction, dt = {a.dt:g} s, no gravity); psi = u_t / "
             "(mu (1 + e) v_n). Walton: beta = min(beta0, -1 + 7 / (2 psi)); taichi_spheres's "
             "default (tangential_restitution = -1) caps a sticking impact at beta = 0.",
             "", "| mu | mu_r | psi | e | beta (LAMMPS) | beta (Walton, beta0 = 0) |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['mu']:g} | {r['mu_r']:g} | {r['psi']:g} | {r['e']:.3f} | "
                     f"{r['beta']:.3f} | {walton_beta(r['psi']):.3f} |")
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--mu", type=float, nargs="+", default=[0.3, 0.6])
    p.add_argument("--mu-r", type=float, nargs="+", default=[0.0, 0.1])
    p.add_argument("--psi", type=float, nargs="+",
                   default=[0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 10.0])
    p.add_argument("--vn", type=float, default=0.5, help="normal impact speed [m/s]")
    p.add_argument("--radius", type=float, default=0.003, help="[m] (scenes/heap.toml)")
    p.add_argument("--density", type=float, default=2500.0, help="[kg/m^3]")
    p.add_argument("--e", type=float, default=0.5, help="restitution")
    p.add_argument("--young", type=float, default=5e9, help="[Pa]")
    p.add_argument("--poisson", type=float, default=0.3)
    p.add_argument("--dt", type=float, default=5e-6, help="LAMMPS time step [s]")
    p.add_argument("--write", action="store_true")
    a = p.parse_args(argv)
    lammps = lammps_silo.import_lammps()
    rows = [dict(wall_impact(lammps, a, mu, mu_r, psi), mu=mu, mu_r=mu_r)
            for mu in a.mu for mu_r in a.mu_r for psi in a.psi]
    text = report(rows, [x for x in argv if x != "--write"], a)
    print(text)
    if a.write:
        write_section(os.path.join(DOCS, "granular.md"), "lammps-walton", text)


if __name__ == "__main__":
    main()
