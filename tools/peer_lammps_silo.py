#!/usr/bin/env python3
"""Silo discharge side by side with LAMMPS (GRANULAR, Hertz-Mindlin): the same lattice
fill, the same silo, orifice, restitution and friction, one thread each.

Both codes start from the same jittered lattice (tools/silo.py ``fill_positions``),
settle it with the orifice closed for ``--settle`` s (untimed), open the orifice and
discharge for ``--duration`` s. taichi_spheres: hard spheres, the contact solver,
Walton impacts (tools/silo.py's scene). LAMMPS: tools/lammps_silo.py (Hertz with
E = 5e9 Pa, nu = 0.3, damping by coefficient of restitution, Mindlin tangential force
with the same mu, dt = 5e-6 s, a thin plate with an orifice and a cylinder wall as
fix wall/gran/region). Reported per code: the steady discharge rate (least squares over
[--transient, duration], tools/silo.py ``steady_rate``), spheres discharged, wall
seconds per simulated second of the discharge, and their ratios.

    python tools/peer_lammps_silo.py                    # ~5 min on 2 cores
    python tools/peer_lammps_silo.py --write            # the 'lammps' section of docs/granular.md
    python tools/peer_lammps_silo.py --step-fraction 0.3 --sweeps 30 --write --section lammps-coarse
    python tools/peer_lammps_silo.py --step-fraction 0.3 --sweeps 10 --position-sweeps 10 \
        --shock --write --section lammps-shock
    python tools/peer_lammps_silo.py --no-scaled-sweeps   # the full caps in every step
    python tools/peer_lammps_silo.py --interleaved     # both discharges in alternate chunks

With ``--interleaved`` the two discharges run in one process in alternate chunks of
``--sample`` simulated s (LAMMPS's first), each code timed over its own chunks only:
this machine's speed drifts by 20-30 % over minutes, and one code run after the other
sees different parts of that drift.
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
import silo  # noqa: E402  (tools/silo.py)
from machine import cpu_name, write_section  # noqa: E402


#: the silo both codes run (tools/silo.py options; more on the command line)
SILO = ["--radius", "0.003", "--silo-radius", "0.045", "--fill", "0.09", "--settle", "0.3",
        "--duration", "0.6", "--threads", "1"]


def settings(rest, orifice: float = 5.0):
    """tools/silo.py's options for SILO plus ``rest``, with ``orifice`` (D / d)."""
    a = silo.parse(SILO + list(rest))
    a.orifice = orifice              # D / d, so that the orifice radius is D/d x r
    return a


def taichi_run(a, x):
    """(times, discharged mass, wall seconds, discharged count, spheres, largest overlap
    after a step / contact distance) of taichi_spheres."""
    settled = silo.settled_fill(a, a.fill, seed=1)
    run = silo.TimedDischarge(a, settled, a.orifice * a.radius)
    while run.chunk():
        pass
    return taichi_result(run, settled)


def taichi_result(run, settled):
    """taichi_run's tuple from a finished silo.TimedDischarge of the fill ``settled``."""
    sim = run.sim
    return (np.array(run.times), np.array(run.mass), run.wall, int(sim.stats["discharged"]),
            len(settled[0]), sim.stats["max_overlap"])


def lammps_run(a, x, between=None):
    """The same for LAMMPS from the lattice x (``between``: lammps_silo.discharge_loop's,
    called after each of its chunks, untimed)."""
    c = a.silo_radius + 0.005
    radius = np.full(len(x), a.radius)
    mass = 2500.0 * 4 / 3 * math.pi * radius ** 3
    dt = 5e-6                                  # LAMMPS's step [s]
    lmp, _, _ = lammps_silo.open_silo(
        x, radius, mass, silo_radius=a.silo_radius, orifice_radius=a.orifice * a.radius,
        floor_z=0.05, top_z=0.05 + a.fill * 2.5, box_lo=(0, 0, 0),
        box_hi=(2 * c, 2 * c, 0.05 + a.fill * 2.5), e=0.5, mu=a.mu, mu_roll=0.0,
        dt=dt, settle=a.settle, threads=1)
    out = lammps_silo.discharge_loop(lmp, dt, a.duration, a.sample, between)
    version = lammps_silo.lammps_version(lmp)
    lmp.close()
    return (np.asarray(out["times"]), np.asarray(out["discharged_mass"]), out["wall_s"],
            int(out["discharged_count"][-1]), version)


def interleaved_runs(a, x):
    """taichi_run's and lammps_run's results, both discharges run in this process in
    alternate chunks of a.sample simulated s (LAMMPS's, then taichi_spheres's, ...),
    so that both codes see the machine in the same state; each code's wall time counts
    its own chunks only."""
    settled = silo.settled_fill(a, a.fill, seed=1)
    run = silo.TimedDischarge(a, settled, a.orifice * a.radius)
    lammps = lammps_run(a, x, run.chunk)
    while run.chunk():                         # (none left: the same chunk count)
        pass
    return taichi_result(run, settled), lammps


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--orifice", type=float, default=5.0, help="orifice diameter / d")
    p.add_argument("--write", action="store_true")
    p.add_argument("--section", default="lammps", help="section of docs/granular.md to write")
    p.add_argument("--interleaved", action="store_true",
                   help="run both discharges in alternate chunks of --sample s (one process)")
    own, rest = p.parse_known_args(argv)
    a = settings(rest, own.orifice)
    c = a.silo_radius + 0.005
    x = silo.fill_positions(a.silo_radius, a.radius, a.fill, 0.05, np.array([c, c]), 1)
    rows = {}
    if own.interleaved:
        taichi, lammps = interleaved_runs(a, x)
    else:
        taichi = taichi_run(a, x)
        lammps = None
    t_times, t_mass, t_wall, t_count, n, t_overlap = taichi
    total = silo.total_mass(a, n)
    rows["taichi_spheres"] = (silo.steady_rate(t_times, t_mass, total, a.transient)[0], t_count,
                              t_wall / (t_times[-1] - t_times[0]))
    l_times, l_mass, l_wall, l_count, version = lammps if lammps else lammps_run(a, x)
    rows[version] = (silo.steady_rate(l_times, l_mass, total, a.transient)[0], l_count,
                     l_wall / a.duration)
    physics = silo.engine_options(a)["tuning"].physics
    caps_text = ", sweep caps scaled with the step" if physics.step_scaled_sweeps \
        else ", full sweep caps"
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread each: "
             f"`python tools/peer_lammps_silo.py {' '.join(x for x in argv if x != '--write')}`".rstrip()
             + (f" (taichi_spheres: step_fraction {a.step_fraction:g}, velocity / position "
                f"sweeps at most {physics.contact_iterations} / "
                f"{physics.position_iterations}"
                f", relaxation {physics.relaxation:g}"
                f"{', shock propagation' if physics.shock_propagation == 'on' else ''}"
                f"{caps_text}"
                f"{', substeps' if physics.substeps else ', no substeps'})"),
             "", f"{n} spheres of d = {2e3 * a.radius:g} mm (2500 kg/m^3, e = 0.5, mu = "
                 f"{a.mu}), silo radius {1e3 * a.silo_radius:g} mm, orifice D = "
                 f"{own.orifice:g} d, settled {a.settle} s, discharge {a.duration} s, rate "
                 f"fitted from {a.transient} s.", "",
             "| code | rate [kg/s] | discharged | wall s / sim s |", "|---|---|---|---|"]
    for name, (rate, count, wall) in rows.items():
        lines.append(f"| {name} | {rate:.4g} | {count} | {wall:.1f} |")
    (rt, _, wt), (rl, _, wl) = rows.values()
    lines += ["", f"Rate taichi_spheres / LAMMPS = {rt / rl:.3f}; LAMMPS / taichi_spheres "
                  f"wall time = {wl / wt:.2f}x. Largest overlap after a taichi_spheres step "
                  f"in the discharge: {t_overlap:.1e} of the contact distance."]
    text = "\n".join(lines)
    print(text)
    if own.write:
        write_section(os.path.join(silo.DOCS, "granular.md"), own.section, text)


if __name__ == "__main__":
    main()
