#!/usr/bin/env python3
"""Angle of repose of a heap poured on a round platform, as a function of sliding
friction mu and rolling friction mu_r.

Each run loads a heap scene (default scenes/heap.toml: spheres run out of a funnel onto
a round platform, the excess running over its edge onto the floor), sets the pair,
wall and geometry friction to mu and the rolling friction to mu_r, simulates until
``--duration`` s (or until the kinetic energy per sphere falls below ``--rest`` J after
half of it), and measures the angle from the heap's surface profile: around the
platform's axis, the top z + r of the highest sphere on the platform in radial bins
one diameter wide; a straight line fitted to that profile between 20 % and 80 % of the
heap's height above the platform (no cap, no toe) gives the slope, and the angle of
repose is atan(-slope). The fixed-base angle (the classic measure on a platform of
radius R) is atan((H - d) / R): H the heap's height above the platform, d the largest
diameter (the top of a sphere resting at the platform's edge): the mean slope from the
top to the edge, defined also where the profile has fewer than three bins between 20 %
and 80 % of the height (a flat-topped deposit, where it is no angle of repose).

With ``--seeds``, each (mu, mu_r) is poured once per seed (every [[pour]] table of the
scene draws its positions and velocities from that seed), and the report adds the mean
and the standard deviation over the pours.

    python tools/heap.py                               # mu in 0.3 0.5 0.7, mu_r in 0 0.1
    python tools/heap.py --mu 0.5 --mu-r 0.1 --no-write
    python tools/heap.py --mu 0.3 0.6 --mu-r 0.1 --seeds 7 8 9
    python tools/heap.py --mu 0.3 --mu-r 0.1 --flat-platform   # the platform as LAMMPS's disc
    python tools/heap.py --mu 0.3 --mu-r 0.1 --beta0 0.4       # Walton's beta0 in impacts
    python tools/heap.py --write                       # the 'heap' section of docs/granular.md
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import sys
import time
import tomllib

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import DEFAULT  # noqa: E402
from taichi_spheres.geometry import with_material  # noqa: E402
from taichi_spheres.scenefile import scene_from_dict  # noqa: E402
from machine import cpu_name, write_section  # noqa: E402  (tools/machine.py)

DOCS = os.path.join(os.path.dirname(__file__), "..", "docs")
#: an outside cone shorter than this fraction of its radius is a platform, a disc in
#: LAMMPS (tools/peer_lammps_heap.py)
FLAT = 0.05


def heap_scene(path, seed=None, flat=False):
    """The scene of the file at path; with seed (an int), its k-th [[pour]] table draws
    from seed + k instead of its own seed; with flat, its platforms flattened to
    LAMMPS's discs (as_lammps_disc)."""
    if seed is None:
        scene = ts.load_scene(path)
    else:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
        for k, pour in enumerate(data.get("pour", [])):
            pour["seed"] = int(seed) + k
        scene = scene_from_dict(data, source=str(path))
    if flat:
        scene = scene.replace(geometry=tuple(as_lammps_disc(g) for g in scene.geometry))
    return scene


def as_lammps_disc(g):
    """Geometry object g, or where LAMMPS has a disc for it (lammps_region: a flat
    outside cone along z) a cone 1 um tall about the disc's top (the cone's mean
    height), so that spheres resting on LAMMPS's disc rest on it."""
    if not isinstance(g, ts.Cone) or isinstance(g, ts.Cylinder) or g.inside or \
            g.length >= FLAT * max(g.radius_at_point, g.radius_at_end):
        return g
    up = float(np.asarray(g.axis, float)[2])
    top = float(g.point[2]) + 0.5 * up * g.length
    point = np.array([g.point[0], g.point[1], top - 0.5 * up * 1e-6])
    return ts.Cone(point, g.axis, g.radius_at_point, g.radius_at_end, 1e-6, inside=False,
                   restitution=g.restitution, friction=g.friction)


def fixed_base_angle(height, base_radius, diameter) -> float:
    """Fixed-base angle of repose [deg] of a heap ``height`` [m] high (its top sphere's top
    above the platform) on a platform of radius ``base_radius`` [m]: atan((height -
    diameter) / base_radius), diameter [m] the height of a sphere resting at the edge;
    0 for a single layer."""
    return math.degrees(math.atan(max(height - diameter, 0.0) / base_radius))


def surface_profile(x, radius, centre, bin_width) -> tuple:
    """(bin centres [m], heights [m]): the highest z + r per radial bin around centre."""
    rho = np.hypot(x[:, 0] - centre[0], x[:, 1] - centre[1])
    top = x[:, 2] + radius
    bins = np.floor(rho / bin_width).astype(int)
    edges, heights = [], []
    for b in range(bins.max() + 1):
        sel = bins == b
        if sel.any():
            edges.append((b + 0.5) * bin_width)
            heights.append(top[sel].max())
    return np.array(edges), np.array(heights)


def repose_angle(x, radius, floor=0.0, below=math.inf, centre=None, within=math.inf) -> tuple:
    """(angle [deg], height [m], samples) of the heap of the spheres x (N, 3), radii (N,)
    between z = floor and z = ``below`` (not those left in a funnel), within ``within``
    [m] of the heap's axis through ``centre`` (x, y; None: the spheres' mean), on a base
    at z = floor (module docstring); nan with fewer than 3 bins on the slope."""
    if centre is None:
        centre = x[x[:, 2] < below, :2].mean(axis=0)
    rho = np.hypot(x[:, 0] - centre[0], x[:, 1] - centre[1])
    on_floor = (x[:, 2] < below) & (x[:, 2] > floor) & (rho < within)
    if not on_floor.any():
        return math.nan, 0.0, 0
    rho, height = surface_profile(x[on_floor], radius[on_floor], centre, 2 * radius.max())
    height = height - floor
    top = height.max()
    use = (height > 0.2 * top) & (height < 0.8 * top)
    if use.sum() < 3:
        return math.nan, float(top), int(use.sum())
    slope = np.polyfit(rho[use], height[use], 1)[0]
    return float(math.degrees(math.atan(-slope))), float(top), int(use.sum())


def base_angle(base, height, radius) -> float:
    """fixed_base_angle of a heap ``height`` [m] high on the base of repose_angle's
    keywords ``base`` (its ``within`` the platform's radius; nan without one)."""
    within = base.get("within", math.inf)
    if not math.isfinite(within):
        return math.nan
    return fixed_base_angle(height, within, 2 * float(np.max(radius)))


def summarise(rows, keys=("mu", "mu_r")) -> list:
    """One dict per distinct ``keys`` of rows: the keys, pours n (those with a finite
    height: a failed run has none), and the mean and standard deviation (ddof 1; nan
    for one pour) of angle (over the pours the profile fit measured: fits), base_angle
    and height."""
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    out = []
    for key, group in groups.items():
        s = dict(zip(keys, key), n=sum(math.isfinite(r["height"]) for r in group))
        for name in ("angle", "base_angle", "height"):
            v = np.array([r[name] for r in group], float)
            v = v[np.isfinite(v)]
            s[name] = float(v.mean()) if v.size else math.nan
            s[name + "_sd"] = float(v.std(ddof=1)) if v.size > 1 else math.nan
            if name == "angle":
                s["fits"] = int(v.size)
        out.append(s)
    return out


def summary_lines(rows, keys=("mu", "mu_r")) -> list:
    """The markdown lines of the table of means ± standard deviations over the pours
    (summarise by keys: mu, mu_r, then any other key as a column); [] when no (mu,
    mu_r) was poured more than once."""
    summary = summarise(rows, keys)
    if not any(s["n"] > 1 for s in summary):
        return []
    head = "| " + " | ".join(keys) + " | pours | profile angle [deg] (fits) | " \
        "fixed-base angle [deg] | heap height [mm] |"
    lines = ["", "Mean ± standard deviation over the pours (profile angle over the pours it "
                 "could fit):", "", head, "|---" * (len(keys) + 4) + "|"]
    for s in summary:
        cells = [f"{s[k]:g}" if isinstance(s[k], float) else str(s[k]) for k in keys]
        lines.append("| " + " | ".join(cells) + f" | {s['n']} | "
                     f"{mean_sd(s['angle'], s['angle_sd'])} ({s['fits']}) | "
                     f"{mean_sd(s['base_angle'], s['base_angle_sd'])} | "
                     f"{mean_sd(s['height'], s['height_sd'], 1e3)} |")
    return lines


def mean_sd(value, sd, scale=1.0, digits=1) -> str:
    """'value ± sd' (scaled) for a report; just the value where sd is nan."""
    if not math.isfinite(sd):
        return f"{scale * value:.{digits}f}"
    return f"{scale * value:.{digits}f} ± {scale * sd:.{digits}f}"


def run_heap(scene, mu, mu_r, duration, rest, threads, base, options=None) -> dict:
    """Simulate the heap scene with friction mu and rolling friction mu_r; returns the
    angle, heap height, time, wall seconds and the largest overlap. options:
    step_fraction and Rules fields (contact_iterations, ...) to change."""
    shapes = [with_material(g, g.restitution, mu) for g in scene.geometry]
    scene = scene.replace(friction=mu, wall_friction=None, rolling_friction=mu_r,
                          geometry=shapes)
    options = dict(options or {})
    step_fraction = options.pop("step_fraction", None)
    extra = {} if step_fraction is None else dict(step_fraction=step_fraction)
    sim = ts.Simulation(scene, threads=threads, tuning=DEFAULT.with_(**options), **extra)
    t0 = time.perf_counter()
    while sim.time < duration - 1e-12:
        sim.advance(0.1)
        st = sim.state()
        ke = ts.observe.kinetic_energy(st) / st.x.shape[0]
        if sim.time > 0.5 * duration and ke < rest:
            break
    seconds = time.perf_counter() - t0
    st = sim.state()
    angle, height, samples = repose_angle(st.x, st.radius, **base)
    return dict(mu=mu, mu_r=mu_r, angle=angle, height=height, samples=samples,
                base_angle=base_angle(base, height, st.radius),
                options=options, time=sim.time,
                sweeps=sim.stats["contact_iterations"] / max(sim.stats["contact_steps"], 1), wall_seconds=seconds, max_overlap=sim.stats["max_overlap"],
                ke_per_sphere=float(ts.observe.kinetic_energy(st) / st.x.shape[0]))


def report(rows, argv, threads, scene_path) -> str:
    """Markdown tables of the runs and, over several pours, their means (docs/granular.md
    section 'heap')."""
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, {threads} thread(s): "
             f"`python tools/heap.py {' '.join(argv)}`".rstrip(),
             "", f"Scene `{scene_path}`; profile angle from the surface profile between 20 % "
                 "and 80 % of the heap's height above the platform; fixed-base angle "
                 "atan((H - d) / R), H the heap's height, R the platform's radius. Wall time: "
                 "the whole run.", "",
             "| seed | mu | mu_r | profile angle [deg] | fixed-base angle [deg] | heap height "
             "[mm] | simulated [s] | wall [s] | max overlap / d |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        seed = "scene" if r.get("seed") is None else r["seed"]
        lines.append(f"| {seed} | {r['mu']:g} | {r['mu_r']:g} | {r['angle']:.1f} | "
                     f"{r['base_angle']:.1f} | {1e3 * r['height']:.1f} | {r['time']:.2f} | "
                     f"{r['wall_seconds']:.0f} | {r['max_overlap']:.1e} |")
    lines += summary_lines(rows)
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=os.path.join(os.path.dirname(__file__), "..", "scenes",
                                                   "heap.toml"))
    p.add_argument("--mu", type=float, nargs="+", default=[0.3, 0.5, 0.7])
    p.add_argument("--mu-r", type=float, nargs="+", default=[0.0, 0.1])
    p.add_argument("--duration", type=float, default=3.0, help="longest run [s]")
    p.add_argument("--rest", type=float, default=1e-9, help="kinetic energy per sphere "
                   "[J] below which the heap counts as settled")
    p.add_argument("--below", type=float, default=0.195, help="spheres above this height "
                   "[m] (in the funnel) are not part of the heap")
    p.add_argument("--base", type=float, nargs=4, default=(0.14, 0.15, 0.15, 0.06),
                   metavar=("Z", "X", "Y", "RADIUS"), help="the heap's base: its height "
                   "[m], centre (x, y) [m] and radius [m] (scenes/heap.toml's platform)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--step-fraction", type=float, default=None,
                   help="largest move per step / smallest radius (default: the engine's)")
    p.add_argument("--iterations", type=int, default=None,
                   help="contact solver velocity sweeps per step at most (Rules)")
    p.add_argument("--flat-platform", action="store_true",
                   help="flatten the platform cone to LAMMPS's disc (a cone 1 um tall "
                        "about its mean height), as tools/peer_lammps_heap.py's LAMMPS has it")
    p.add_argument("--beta0", type=float, default=None,
                   help="tangential restitution of impacts, Walton's beta0 in [-1, 1] "
                        "(default: the scene's)")
    p.add_argument("--seeds", type=int, nargs="+", default=[None],
                   help="pour once per seed (default: once, the scene's own seeds)")
    p.add_argument("--write", action="store_true")
    p.add_argument("--no-write", dest="write", action="store_false")
    p.add_argument("--section", default="heap",
                   help="the docs/granular.md section --write replaces")
    a = p.parse_args(argv)
    base = dict(floor=a.base[0], below=a.below, centre=a.base[1:3], within=a.base[3])
    options = {k: v for k, v in (("step_fraction", a.step_fraction),
                                 ("contact_iterations", a.iterations)) if v}
    rows = []
    for seed in a.seeds:
        scene = heap_scene(a.scene, seed, a.flat_platform)
        if a.beta0 is not None:
            scene = scene.replace(tangential_restitution=a.beta0)
        for mu in a.mu:
            for mu_r in a.mu_r:
                rows.append(dict(run_heap(scene, mu, mu_r, a.duration, a.rest, a.threads,
                                          base, options), seed=seed))
                print(rows[-1], flush=True)
    text = report(rows, [x for x in argv if x != "--write"], a.threads,
                  os.path.relpath(a.scene, os.path.join(os.path.dirname(__file__), "..")))
    print(text)
    if a.write:
        write_section(os.path.join(DOCS, "granular.md"), a.section, text)


if __name__ == "__main__":
    main()
