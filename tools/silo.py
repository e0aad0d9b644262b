#!/usr/bin/env python3
"""Silo discharge: rate through orifices of several diameters, fitted to Beverloo's law.

A flat-bottomed cylindrical silo (radius R, default 50 mm) is filled with frictional
spheres (radius r, default 2.5 mm, density 2500 kg/m^3, e = 0.5, mu = 0.5 for pairs and
walls) on a jittered lattice up to a fill height and settled with the orifice closed.
Then, from that settled state, the floor gets a circular orifice of diameter D centred
on the axis and the spheres that fall through it enter a sink below the floor
(``ts.Sink``). The discharged mass is sampled every ``--sample`` s; the rate W [kg/s]
is the least-squares slope over the steady part: after ``--transient`` s and while
less than half of the fill has left (the free surface still far above the orifice).

Beverloo's law W = C rho_b sqrt(g) (D - k d)^(5/2) (Beverloo, Leniger & van de Velde
1961; Mankoc et al. 2007) is fitted as a straight line W^(2/5) = (C rho_b sqrt(g))^(2/5)
(D - k d): slope and intercept give C and k. rho_b is the bulk density of the settled
fill (its mass over the volume of the cylinder up to the mean height of its top
layer). With ``--fills`` two fill heights at one orifice show whether W depends on the
fill height.

    python tools/silo.py                       # D = 5..8 d, ~20-40 min on 2 cores
    python tools/silo.py --orifices 5 6 --duration 0.4 --no-write     # a quick look
    python tools/silo.py --write               # the 'silo' section of docs/granular.md

Reported: N, bulk density, per orifice the rate, the fit's C and k, the wall seconds
per simulated second of the discharges, the machine (tools/machine.py) and the command.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from machine import cpu_name, tuning_args, write_section  # noqa: E402  (tools/machine.py)

G = 9.81
DOCS = os.path.join(os.path.dirname(__file__), "..", "docs")


def fill_positions(silo_radius, r, height, floor, centre, seed) -> np.ndarray:
    """Centres (N, 3) [m] on a square lattice of spacing 2.2 r, jittered by 0.05 r,
    inside a cylinder of radius silo_radius - r about ``centre`` (x, y), from the floor
    up to floor + height."""
    rng = np.random.default_rng(seed)
    step = 2.2 * r
    xs = np.arange(-silo_radius + r * 1.1, silo_radius - r, step)
    zs = np.arange(floor + 1.1 * r, floor + height, step)
    grid = np.array(np.meshgrid(xs, xs, zs, indexing="ij")).reshape(3, -1).T
    grid = grid[np.hypot(grid[:, 0], grid[:, 1]) < silo_radius - 1.1 * r]
    grid[:, :2] += centre
    grid += rng.uniform(-0.05 * r, 0.05 * r, grid.shape)
    return grid


def silo_scene(x, v, omega, a, hole, radius=None):
    """The silo of settings ``a`` with spheres x, v, omega ((N, 3)) and an orifice of
    radius ``hole`` [m] (None: closed)."""
    c = a.silo_radius + 0.005
    floor = 0.05
    top = floor + a.fill * 2.5
    return ts.Scene.from_arrays(
        x, v, a.radius if radius is None else radius, density=2500.0,
        box=((0, 0, 0), (2 * c, 2 * c, top)), restitution=0.5, wall_restitution=0.5,
        friction=a.mu, omega=omega, name="silo",
        geometry=[ts.Plane((c, c, floor), (0, 0, 1), hole=hole),
                  ts.Cylinder((c, c, floor), (0, 0, 1), a.silo_radius, length=top - floor)],
        sinks=[ts.Sink((0, 0, 0), (2 * c, 2 * c, floor - 4 * a.radius))])


def engine_options(a) -> dict:
    """Simulation keywords of the command line: threads, step_fraction, the contact
    solver's velocity and position sweep caps and over-relaxation (None: the defaults),
    its shock propagation pass, substeps (Rules.substeps) and sweep caps scaled with the
    step (Rules.step_scaled_sweeps), and --tuning's other options."""
    tuning = Tuning()
    if a.relaxation is not None:
        tuning = tuning.with_(relaxation=a.relaxation)
    if a.sweeps is not None:
        tuning = tuning.with_(contact_iterations=a.sweeps)
    if a.position_sweeps is not None:
        tuning = tuning.with_(position_iterations=a.position_sweeps)
    if a.shock:
        tuning = tuning.with_(shock_propagation="on")
    if a.substeps is not None:
        tuning = tuning.with_(substeps=a.substeps)
    if a.scaled_sweeps is not None:
        tuning = tuning.with_(step_scaled_sweeps=a.scaled_sweeps)
    tuning = tuning.with_(**a.tuning)
    return dict(threads=a.threads, step_fraction=a.step_fraction, tuning=tuning)


def settled_fill(a, height, seed):
    """(x, v, omega, rho_b, seconds, x_fill, top): the fill settled with the orifice
    closed, the lattice it started from, and the settled fill's height above the floor
    [m] (the mean height of its top 5 % of spheres)."""
    c = a.silo_radius + 0.005
    x = fill_positions(a.silo_radius, a.radius, height, 0.05, np.array([c, c]), seed)
    sim = ts.Simulation(silo_scene(x, np.zeros_like(x), None, a, None), **engine_options(a))
    t0 = time.perf_counter()
    sim.advance(a.settle)
    st = sim.state()
    top = np.sort(st.x[:, 2])[-max(1, int(0.05 * len(x))):].mean() - 0.05
    rho_b = float(st.mass.sum() / (math.pi * a.silo_radius ** 2 * top))
    return st.x, st.v, st.omega, rho_b, time.perf_counter() - t0, x, top


def discharging(a, settled, hole):
    """The Simulation of the settled fill (settled_fill) with an orifice of radius
    ``hole`` [m] open, at the start of its discharge."""
    x, v, omega = settled[:3]
    # the scene is built on the (valid) lattice and continues from the settled state:
    # that one may hold overlaps within the contact solver's tolerance, which a new
    # Scene would refuse
    start = settled[5]
    sim = ts.Simulation(silo_scene(start, np.zeros_like(start), None, a, hole),
                        **engine_options(a))
    sim.set_state(x, v, omega=omega)
    return sim


class TimedDischarge:
    """A discharge through an orifice of radius ``hole`` from the settled state, run in
    timed chunks of a.sample s (``chunk``: one, until a.duration; the first, which
    compiles, untimed), so that a caller can alternate them with another code's."""

    def __init__(self, a, settled, hole):
        self.a = a
        self.sim = discharging(a, settled, hole)
        self.sim.advance(a.sample)              # compile outside the timed chunks
        self.times, self.mass = [self.sim.time], [self.sim.stats["discharged_mass"]]
        self.wall = 0.0

    def chunk(self) -> bool:
        """Run the next chunk (timed) and sample; False when the discharge is over."""
        if self.sim.time >= self.a.duration - 1e-12:
            return False
        t0 = time.perf_counter()
        self.sim.advance(self.a.sample)
        self.wall += time.perf_counter() - t0
        self.times.append(self.sim.time)
        self.mass.append(self.sim.stats["discharged_mass"])
        return True


def discharge(a, settled, hole):
    """Times [s], discharged mass [kg], wall seconds and the Simulation of a discharge
    through an orifice of radius ``hole`` from the settled state (TimedDischarge's
    chunks one after the other)."""
    run = TimedDischarge(a, settled, hole)
    while run.chunk():
        pass
    return np.array(run.times), np.array(run.mass), run.wall, run.sim


def total_mass(a, n: int) -> float:
    """Mass [kg] of n spheres of radius a.radius (2500 kg/m^3, silo_scene's density)."""
    return float(n * 2500.0 * 4 / 3 * math.pi * a.radius ** 3)


def steady_rate(times, mass, total, transient) -> tuple:
    """(W [kg/s], samples): least-squares slope of mass(t) after ``transient`` s while
    less than half of ``total`` [kg] has left; (nan, n) with fewer than 4 samples."""
    use = (times >= transient) & (mass <= 0.5 * total)
    if use.sum() < 4:
        return math.nan, int(use.sum())
    slope = np.polyfit(times[use], mass[use], 1)[0]
    return float(slope), int(use.sum())


def beverloo_fit(diameters, rates, rho_b, d) -> tuple:
    """(C, k) of W = C rho_b sqrt(g) (D - k d)^(5/2) by a straight line through
    (D, W^(2/5))."""
    slope, intercept = np.polyfit(diameters, np.asarray(rates) ** 0.4, 1)
    k = -intercept / slope / d
    c = slope ** 2.5 / (rho_b * math.sqrt(G))
    return float(c), float(k)


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--radius", type=float, default=0.0025, help="sphere radius [m]")
    p.add_argument("--silo-radius", type=float, default=0.05, help="silo radius [m]")
    p.add_argument("--fill", type=float, default=0.12, help="fill height [m]")
    p.add_argument("--fills", type=float, nargs="*", default=[0.06],
                   help="other fill heights [m] for the height test at the first orifice")
    p.add_argument("--orifices", type=float, nargs="+", default=[5, 6, 7, 8],
                   help="orifice diameters in sphere diameters")
    p.add_argument("--mu", type=float, default=0.5, help="friction coefficient")
    p.add_argument("--settle", type=float, default=0.4, help="settling time [s]")
    p.add_argument("--duration", type=float, default=0.8, help="discharge time [s]")
    p.add_argument("--transient", type=float, default=0.15, help="start of the fit [s]")
    p.add_argument("--sample", type=float, default=0.02, help="sampling interval [s]")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--step-fraction", type=float, default=0.1,
                   help="Simulation step_fraction (default 0.1, the Simulation's)")
    p.add_argument("--sweeps", type=int, default=None,
                   help="the contact solver's velocity sweep cap (default: Rules')")
    p.add_argument("--position-sweeps", type=int, default=None,
                   help="the contact solver's position sweep cap (default: Rules')")
    p.add_argument("--relaxation", type=float, default=None,
                   help="the contact solver's over-relaxation (default: Rules')")
    p.add_argument("--shock", action="store_true",
                   help="switch on the contact solver's shock propagation pass")
    p.add_argument("--substeps", action=argparse.BooleanOptionalAction, default=None,
                   help="drift and impacts in substeps, the contact solver once per step "
                        "(Rules.substeps; default: Rules', on); --no-substeps: one drift "
                        "per solve")
    p.add_argument("--scaled-sweeps", action=argparse.BooleanOptionalAction, default=None,
                   help="scale each step's sweep caps with its length "
                        "(Rules.step_scaled_sweeps; default: Rules', on); "
                        "--no-scaled-sweeps: the full caps in every step")
    p.add_argument("--tuning", nargs="+", default=None, metavar="NAME=VALUE",
                   help="other engine options (config.Tuning fields), e.g. "
                        "discharge_in_place=False")
    p.add_argument("--write", action="store_true", help="write docs/granular.md's section")
    p.add_argument("--no-write", dest="write", action="store_false")
    p.add_argument("--json", help="also write the results to this JSON file")
    p.add_argument("--section", default="silo", help="the section of docs/granular.md "
                   "--write replaces ('silo-fill': the fill-height run)")
    a = p.parse_args(argv)
    a.tuning = tuning_args(a.tuning, p)
    return a


def run(a) -> dict:
    """Settle, discharge through each orifice (and the other fills), fit Beverloo."""
    d = 2 * a.radius
    out = dict(settings=vars(a).copy(), orifices=[], fills=[])
    settled = settled_fill(a, a.fill, seed=1)
    out.update(n=len(settled[0]), rho_b=settled[3], settle_seconds=settled[4],
               settled_height=settled[6])
    for ratio in a.orifices:
        times, mass, seconds, sim = discharge(a, settled, ratio * d / 2)
        total = total_mass(a, settled[0].shape[0])
        w, used = steady_rate(times, mass, total, a.transient)
        out["orifices"].append(dict(D_over_d=ratio, rate=w, samples=used,
                                    wall_per_sim=seconds / (times[-1] - times[0]),
                                    discharged=int(sim.stats["discharged"])))
        print(json.dumps(out["orifices"][-1]), flush=True)
    ok = [o for o in out["orifices"] if math.isfinite(o["rate"])]
    if len(ok) >= 2:
        out["C"], out["k"] = beverloo_fit([o["D_over_d"] * d for o in ok],
                                          [o["rate"] for o in ok], settled[3], d)
    for height in a.fills:
        other = settled_fill(a, height, seed=2)
        times, mass, seconds, sim = discharge(a, other, a.orifices[0] * d / 2)
        total = total_mass(a, other[0].shape[0])
        w, used = steady_rate(times, mass, total, a.transient)
        out["fills"].append(dict(fill=height, n=len(other[0]), rate=w, samples=used,
                                 settled_height=other[6]))
    return out


def plot_beverloo(out, path) -> bool:
    """W^(2/5) against D / d with the Beverloo line of the fit, as a PNG at ``path``;
    False when matplotlib is missing or there is no fit."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    if "C" not in out:
        return False
    a, d = out["settings"], 2 * out["settings"]["radius"]
    ratio = np.array([o["D_over_d"] for o in out["orifices"]])
    rate = np.array([o["rate"] for o in out["orifices"]])
    line = np.linspace(out["k"], ratio.max() * 1.05, 50)
    fit = out["C"] * out["rho_b"] * math.sqrt(G) * (np.maximum(line - out["k"], 0) * d) ** 2.5
    fig, ax = plt.subplots(figsize=(5.5, 4.0), dpi=100)
    ax.plot(ratio, rate ** 0.4, "o", label="tools/silo.py")
    ax.plot(line, fit ** 0.4, "-", label=f"Beverloo, C = {out['C']:.3f}, k = {out['k']:.2f}")
    ax.set_xlabel("orifice diameter D / d")
    ax.set_ylabel("discharge rate W^(2/5) [(kg/s)^(2/5)]")
    ax.set_title(f"Silo radius {1e3 * a['silo_radius']:g} mm, d = {2e3 * a['radius']:g} mm, "
                 f"mu = {a['mu']:g}", fontsize=10)
    ax.set_xlim(0, None)
    ax.set_ylim(0, None)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return True


def _fill_text(run, a) -> str:
    """'48 mm (0.80 silo widths)' of a run's settled fill height."""
    top = run["settled_height"]
    return f"{top * 1e3:.0f} mm ({top / (2 * a['silo_radius']):.2f} silo widths)"


def report(out, argv) -> str:
    """Markdown of a run (docs/granular.md section 'silo')."""
    a = out["settings"]
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, {a['threads']} thread(s): "
             f"`python tools/silo.py {' '.join(argv)}`".rstrip() + "",
             "",
             f"Silo radius {a['silo_radius'] * 1e3:g} mm, {out['n']} spheres of diameter "
             f"d = {2e3 * a['radius']:g} mm (2500 kg/m^3, e = 0.5, mu = {a['mu']}), a lattice "
             f"fill {a['fill'] * 1e3:g} mm high settled to {_fill_text(out, a)}, bulk density "
             f"rho_b = {out['rho_b']:.0f} kg/m^3; rate fitted over [{a['transient']}, "
             f"{a['duration']}] s.",
             "",
             "| D / d | W [kg/s] | samples | discharged | wall s / sim s |",
             "|---|---|---|---|---|"]
    for o in out["orifices"]:
        lines.append(f"| {o['D_over_d']:g} | {o['rate']:.4g} | {o['samples']} | "
                     f"{o['discharged']} | {o['wall_per_sim']:.1f} |")
    if "C" in out:
        lines += ["", f"Beverloo fit: **C = {out['C']:.3f}, k = {out['k']:.2f}** "
                      "(glass beads in experiments: C = 0.55-0.65, k = 1.3-2.9; "
                      "Mankoc et al. 2007)."]
    for f in out["fills"]:
        first = out["orifices"][0]["rate"]
        lines += ["", f"Lattice fill {f['fill'] * 1e3:g} mm ({f['n']} spheres) settled to "
                      f"{_fill_text(f, a)}, D = {a['orifices'][0]:g} d: W = "
                      f"{f['rate']:.4g} kg/s, {100 * (f['rate'] / first - 1):+.1f} % from the "
                      f"first fill."]
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    a = parse(argv)
    out = run(a)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)
    shown = [x for k, x in enumerate(argv) if x != "--write" and x != "--json"
             and (k == 0 or argv[k - 1] != "--json")]
    text = report(out, shown)
    print(text)
    if a.write:
        write_section(os.path.join(DOCS, "granular.md"), a.section, text)
        if plot_beverloo(out, os.path.join(DOCS, f"{a.section}_beverloo.png")):
            print(f"wrote docs/{a.section}_beverloo.png")


if __name__ == "__main__":
    main()
