#!/usr/bin/env python3
"""Heaps side by side with LAMMPS (GRANULAR, Hertz-Mindlin with sds rolling and
twisting resistance): the same scene, friction and rolling friction, the heap's angle
and height from both codes, one thread each.

Setups (``--setup``):
- ``funnel`` (default): scenes/heap.toml as tools/heap.py runs it: spheres run out of
  a funnel (a cone below a cylinder) onto a round platform (a flat cone, spheres
  outside it), building a heap whose angle is measured on the platform. Its geometry
  becomes LAMMPS regions under fix wall/gran/region: containers (``inside``) the
  lateral surface of a ``cone`` or ``cylinder`` along z with open ends, obstacles
  closed solids; the platform (a cone 1 mm tall, 60 mm in radius) a disc at its mean
  height, because LAMMPS lets spheres through so shallow a cone.
- ``column``: a column of spheres on a jittered square lattice (spacing 2.2 r, tools/
  lammps_silo.py ``fill_lattice``) inside a radius ``--column``, released at rest on
  the box floor, collapsing into a low deposit.
Both codes start from the same positions and velocities. The angle is measured from
the surface profile as in tools/heap.py (the highest sphere top in radial bins one
diameter wide, a straight line between 20 % and 80 % of the heap's height), and on the
funnel's platform also as the fixed-base angle atan((H - d) / R). With several
``--seed`` values, each (mu, mu_r) runs once per seed (the funnel's pour, or the
column's lattice jitter, drawn from it) and the report adds means and standard
deviations per code.

With ``--hold SECONDS``, taichi_spheres also starts from LAMMPS's final heap (the
spheres on the platform, at rest, radii shrunk by the largest LAMMPS overlap plus
5e-4 so that no two start overlapping, masses kept, the platform flattened to
LAMMPS's disc) and runs it SECONDS more with the same mu and mu_r: whether it holds
LAMMPS's heap (statics) or lets it slump, apart from how each code builds one.
taichi_spheres: hard spheres, Walton impacts, the contact solver with Coulomb friction
and rolling resistance (torque <= mu_r r_eff F_n). LAMMPS: tools/lammps_silo.py's
contact model (Hertz, E = 5e9 Pa, nu = 0.3, damping from the restitution, Mindlin
friction mu, sds rolling and twisting limited to mu_r r_eff F_n) for pairs, the box's
faces (fix wall/gran planes) and the geometry, dt = 5e-6 s. LAMMPS runs in a second
process beside taichi_spheres, one thread each (a machine with two cores or more).

    python tools/peer_lammps_heap.py --mu 0.3 0.6 --mu-r 0.1
    python tools/peer_lammps_heap.py --mu 0.3 0.6 --mu-r 0.1 --seed 7 8 9
    python tools/peer_lammps_heap.py --mu 0.6 --hold 1.0
    python tools/peer_lammps_heap.py --mu 0.3 --codes lammps --roll-stiffness 0.1
    python tools/peer_lammps_heap.py --mu 0.3 --codes lammps --no-twisting
    python tools/peer_lammps_heap.py --setup column --count 1500 --duration 1.5
    python tools/peer_lammps_heap.py --write        # the 'peer-heap' section of docs/granular.md
"""
from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import math
import multiprocessing
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import heap  # noqa: E402  (tools/heap.py)
import peer_lammps  # noqa: E402  (tools/peer_lammps.py)
import lammps_silo  # noqa: E402  (tools/lammps_silo.py)
from machine import cpu_name, write_section  # noqa: E402

DENSITY = 2500.0


def column_scene(a, seed=None):
    """(scene, base) of the column setup: spheres at rest in a radius a.column about the
    box's vertical axis, the lattice jittered from seed (None: 1); base: tools/heap.py
    repose_angle arguments."""
    import taichi_spheres as ts
    centre = np.array([a.box / 2, a.box / 2])
    x = lammps_silo.fill_lattice(a.count, a.radius, a.column, 0.0, centre,
                                 seed=1 if seed is None else seed)
    hi = np.array([a.box, a.box, float(x[:, 2].max()) + 2 * a.radius])
    scene = ts.Scene.from_arrays(x, np.zeros_like(x), a.radius, density=DENSITY,
                                 box=(np.zeros(3), hi), gravity=(0, 0, -lammps_silo.G),
                                 restitution=a.e, wall_restitution=a.e)
    return scene, dict(floor=0.0, centre=centre)


def funnel_scene(a, seed=None):
    """(scene, base) of the funnel setup (scenes/heap.toml poured from seed, None: the
    file's own seeds; tools/heap.py's base)."""
    scene = heap.heap_scene(a.scene, seed)
    return scene, dict(floor=0.14, below=0.195, centre=(0.15, 0.15), within=0.06)


def lammps_region(k, g) -> str:
    """LAMMPS region command of geometry object g (a ts.Cone or ts.Cylinder along +z or
    -z, named geo<k>)."""
    import taichi_spheres as ts
    axis = np.asarray(g.axis, float)
    if abs(abs(axis[2]) - 1) > 1e-12:
        raise ValueError(f"geometry[{k}]: only cones and cylinders along z have a region here")
    if isinstance(g, ts.Cylinder):
        r0 = r1 = g.radius
    elif isinstance(g, ts.Cone):
        r0, r1 = g.radius_at_point, g.radius_at_end
    else:
        raise ValueError(f"geometry[{k}]: {type(g).__name__} has no region here")
    z0, z1 = g.point[2], g.point[2] + axis[2] * g.length
    (lo, rlo), (hi, rhi) = sorted([(z0, r0), (z1, r1)])
    if not g.inside and g.length < heap.FLAT * max(r0, r1):
        # a flat cone (a platform): LAMMPS's cone contacts let spheres through so
        # shallow a surface; a disc at its mean height stands for it
        top = 0.5 * (lo + hi)
        return (f"region geo{k} cylinder z {g.point[0]:.10g} {g.point[1]:.10g} "
                f"{max(r0, r1):.10g} {top - 10 * g.length:.10g} {top:.10g} side out units box")
    kind = f"cylinder z {g.point[0]:.10g} {g.point[1]:.10g} {r0:.10g}" if r0 == r1 else \
        f"cone z {g.point[0]:.10g} {g.point[1]:.10g} {rlo:.10g} {rhi:.10g}"
    # a container (inside) is its open lateral surface; an obstacle (outside, such as
    # a platform) a closed solid, so that spheres passing its rim meet its end face
    ends = "side in open 1 open 2" if g.inside else "side out"
    return f"region geo{k} {kind} {lo:.10g} {hi:.10g} {ends} units box"


def taichi_run(a, scene, mu, mu_r, base) -> dict:
    """tools/heap.py's run of the scene with friction mu and rolling friction mu_r."""
    return heap.run_heap(scene, mu, mu_r, a.duration, 0.0, 1, base)


def lammps_run(a, scene, mu, mu_r, base) -> dict:
    """Angle, height and wall seconds of LAMMPS from the scene's spheres and geometry."""
    lammps = lammps_silo.import_lammps()
    n = scene.n
    k, gamma = lammps_silo.rolling_defaults(scene.radius, scene.mass, a.dt)
    # a stiffer or softer spring at the same damping ratio (gamma ~ sqrt(k))
    roll = (k * a.roll_stiffness, gamma * math.sqrt(a.roll_stiffness))
    pad = np.full(3, 4 * float(scene.radius.max()))   # room for LAMMPS's bins
    lmp = lammps_silo.create_system(lammps, scene.x, scene.radius, scene.mass,
                                    scene.box_lo - pad, scene.box_hi + pad, a.dt, 1)
    nl = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nl]) - 1
    lmp.numpy.extract_atom("v")[:nl] = scene.v[ids]
    r = float(scene.radius.mean())
    lmp.command("pair_style granular")
    lmp.command("pair_coeff * * " + lammps_silo.contact_model(
        a.young, 0.3, scene.restitution, mu, mu_r, roll, r / 2, a.twisting))
    wall = lammps_silo.contact_model(a.young, 0.3, scene.wall_restitution, mu, mu_r, roll, r,
                                     a.twisting)
    for k, axis in enumerate("xyz"):
        lmp.command(f"fix wall_{axis} all wall/gran granular {wall} {axis}plane "
                    f"{scene.box_lo[k]:.10g} {scene.box_hi[k]:.10g}")
    for k, g in enumerate(scene.geometry):
        lmp.command(lammps_region(k, g))
        lmp.command(f"fix wall_geo{k} all wall/gran/region granular {wall} region geo{k}")
    lmp.command("run 0 post no")
    t0 = time.perf_counter()
    lmp.command(f"run {int(round(a.duration / a.dt))} pre no post no")
    seconds = time.perf_counter() - t0
    nl = lmp.extract_global("nlocal")
    ids = np.array(lmp.numpy.extract_atom("id")[:nl]) - 1
    x = np.full((n, 3), np.nan)
    x[ids] = np.array(lmp.numpy.extract_atom("x")[:nl])
    version = lammps_silo.lammps_version(lmp)
    lmp.close()
    angle, height, _ = heap.repose_angle(x[ids], scene.radius[ids], **base)
    return dict(angle=angle, height=height, wall_seconds=seconds, lost=n - len(ids),
                base_angle=heap.base_angle(base, height, scene.radius), version=version,
                x=x)


def held_scene(scene, x, below=math.inf, floor=-math.inf):
    """(scene, shrink) of LAMMPS's final positions x (N, 3) [m], nan for a sphere it
    lost: the spheres between ``floor`` minus the largest radius and ``below`` [m] (the
    heap: not those left in the funnel, nor those that ran off the platform, some of
    which lie under it), at rest, their radii times (1 - shrink) with
    shrink the largest pair overlap / (r_i + r_j) plus 5e-4 (doubled until no sphere
    starts overlapping a sphere, wall or object; at most 1 %), masses kept, a platform
    flat as LAMMPS's disc (tools/heap.py as_lammps_disc)."""
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(x[:, 0]) & (x[:, 2] < below) & \
            (x[:, 2] > floor - float(scene.radius.max()))
    x, radius = x[keep], scene.radius[keep]
    pair, _ = peer_lammps.largest_overlaps(x, radius, scene.box_lo, scene.box_hi)
    shrink = pair + 5e-4
    shapes = tuple(heap.as_lammps_disc(g) for g in scene.geometry)
    while True:
        try:
            return scene.replace(x=x, v=np.zeros_like(x), radius=radius * (1 - shrink),
                                 mass=scene.mass[keep], omega=np.zeros_like(x),
                                 material=scene.material[keep], geometry=shapes), shrink
        except ValueError as exc:       # only a start overlap is mended by shrinking
            if "overlap" not in str(exc) and "inside geometry" not in str(exc) or \
                    2 * shrink > 0.01:
                raise
            shrink *= 2


def hold_run(a, scene, x, mu, mu_r, base) -> dict:
    """taichi_spheres run a.hold s from LAMMPS's final heap x (held_scene) with friction
    mu and rolling friction mu_r: tools/heap.py's result, and the shrink used."""
    held, shrink = held_scene(scene, x, base.get("below", math.inf),
                              base.get("floor", -math.inf))
    return dict(heap.run_heap(held, mu, mu_r, a.hold, 0.0, 1, base), shrink=shrink)


def run_both(a, pool, scene, mu, mu_r, base) -> list:
    """[(code, result)] of the codes in a.codes on one scene, LAMMPS in pool's process
    beside taichi_spheres; a LAMMPS run that stops gives nan results and a message."""
    pending = pool.submit(lammps_run, a, scene, mu, mu_r, base) \
        if "lammps" in a.codes else None
    runs = []
    if "taichi_spheres" in a.codes:
        runs.append(("taichi_spheres", taichi_run(a, scene, mu, mu_r, base)))
    if pending is not None:
        try:
            out = pending.result()
        except Exception as exc:           # LAMMPS stopped: say so, go on
            print(f"LAMMPS failed at mu {mu}, mu_r {mu_r}: {exc}", flush=True)
            out = dict(angle=math.nan, height=math.nan, wall_seconds=math.nan,
                       base_angle=math.nan)
        runs.append(("LAMMPS", out))
        if a.hold > 0 and "x" in out:
            runs.append(("taichi_spheres holding LAMMPS's heap",
                         hold_run(a, scene, out["x"], mu, mu_r, base)))
    return runs


def hold_text(rows, a) -> str:
    """The report's sentence on the held heaps (--hold), or ''."""
    if a.hold <= 0:
        return ""
    shrink = max((r["shrink"] for r in rows if math.isfinite(r.get("shrink", math.nan))),
                 default=math.nan)
    return (" *taichi_spheres holding LAMMPS's heap*: LAMMPS's final spheres on the "
            f"platform, at rest, radii shrunk by at most {shrink:.1e} (no overlaps), run "
            f"{a.hold:g} s more with the same mu and mu_r.")


def spring_text(a) -> str:
    """The report's sentence on LAMMPS's rolling and twisting settings when not the
    defaults ('' otherwise)."""
    parts = []
    if a.roll_stiffness != 1.0:
        parts.append(f"rolling and twisting springs {a.roll_stiffness:g} times "
                     "lammps_silo.rolling_defaults' (same damping ratio)")
    if not a.twisting:
        parts.append("no twisting resistance")
    return f" LAMMPS: {', '.join(parts)}." if parts else ""


def report(rows, argv, a, scene, version) -> str:
    """Markdown tables of the runs and, over several seeds, the mean ± standard deviation
    per code (docs/granular.md section 'peer-heap')."""
    what = (f"`{os.path.relpath(a.scene, os.path.join(HERE, '..'))}`" if a.setup == "funnel"
            else f"a column of radius {1e3 * a.column:g} mm released at rest on the floor")
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}, 1 thread each: "
             f"`python tools/peer_lammps_heap.py {' '.join(argv)}`".rstrip(), "",
             f"{scene.n} spheres of d = {2e3 * float(scene.radius[0]):g} mm, {what}; heap "
             f"after {a.duration:g} s. {version}: E = {a.young:g} Pa, nu = 0.3, "
             f"dt = {a.dt:g} s. Profile angle: a line through the surface profile between "
             "20 % and 80 % of the heap's height; fixed-base angle: atan((H - d) / R) on "
             "the platform of radius R." + spring_text(a) + hold_text(rows, a), "",
             "| seed | mu | mu_r | code | profile angle [deg] | fixed-base angle [deg] | "
             "height [mm] | wall s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        seed = "scene" if r.get("seed") is None else r["seed"]
        lines.append(f"| {seed} | {r['mu']:g} | {r['mu_r']:g} | {r['code']} | "
                     f"{r['angle']:.1f} | {r['base_angle']:.1f} | {1e3 * r['height']:.1f} | "
                     f"{r['wall']:.0f} |")
    lines += heap.summary_lines(rows, ("mu", "mu_r", "code"))
    return "\n".join(lines)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--setup", choices=["funnel", "column"], default="funnel")
    p.add_argument("--scene", default=os.path.join(HERE, "..", "scenes", "heap.toml"))
    p.add_argument("--mu", type=float, nargs="+", default=[0.3, 0.6])
    p.add_argument("--mu-r", type=float, nargs="+", default=[0.1])
    p.add_argument("--count", type=int, default=1500)
    p.add_argument("--radius", type=float, default=0.003)
    p.add_argument("--column", type=float, default=0.03, help="column radius [m]")
    p.add_argument("--box", type=float, default=0.3, help="box side [m]")
    p.add_argument("--duration", type=float, default=3.0)
    p.add_argument("--e", type=float, default=0.5)
    p.add_argument("--young", type=float, default=5e9)
    p.add_argument("--dt", type=float, default=5e-6)
    p.add_argument("--seed", type=int, nargs="+", default=[None],
                   help="one run per seed: the funnel's pour (default: the scene file's "
                        "seeds) or the column's lattice jitter (default 1)")
    p.add_argument("--codes", nargs="+", default=["taichi_spheres", "lammps"])
    p.add_argument("--hold", type=float, default=0.0, help="also run taichi_spheres this "
                   "long [s] from LAMMPS's final heap (0: not)")
    p.add_argument("--roll-stiffness", type=float, default=1.0, metavar="F",
                   help="LAMMPS's rolling (and twisting) spring F times "
                        "lammps_silo.rolling_defaults', same damping ratio")
    p.add_argument("--no-twisting", dest="twisting", action="store_false",
                   help="LAMMPS without twisting resistance")
    p.add_argument("--write", action="store_true")
    p.add_argument("--section", default="peer-heap",
                   help="the docs/granular.md section --write replaces")
    a = p.parse_args(argv)
    if not (math.isfinite(a.roll_stiffness) and a.roll_stiffness > 0):
        p.error("--roll-stiffness takes a finite factor > 0")
    rows, version = [], "LAMMPS"
    # LAMMPS runs in a second process beside taichi_spheres (one core each)
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as pool:
        for seed in a.seed:
            scene, base = (funnel_scene if a.setup == "funnel" else column_scene)(a, seed)
            for mu in a.mu:
                for mu_r in a.mu_r:
                    for code, out in run_both(a, pool, scene, mu, mu_r, base):
                        version = out.get("version", version)
                        rows.append(dict(seed=seed, mu=mu, mu_r=mu_r, code=code,
                                         wall=out["wall_seconds"], angle=out["angle"],
                                         base_angle=out["base_angle"],
                                         height=out["height"],
                                         shrink=out.get("shrink", math.nan)))
                        print(rows[-1], flush=True)
    text = report(rows, [s for s in argv if s != "--write"], a, scene, version)
    print(text)
    if a.write:
        write_section(os.path.join(HERE, "..", "docs", "granular.md"), a.section, text)


if __name__ == "__main__":
    main()
