"""Ready-made scenes for tests, benchmarks and examples (numpy only, reproducible)."""
from __future__ import annotations

import math

import numpy as np

from .geometry import Cylinder
from .materials import Material
from .scene import Scene

__all__ = ["gas", "same_bits_scene", "same_bits_case_scene", "fcc_block", "ball_on_block",
           "box_pile", "PILE_RADIUS"]


def gas(n, packing=0.3, radius=0.5, periodic=True, gravity=(0.0, 0.0, 0.0), restitution=1.0,
        wall_restitution=1.0, speed=1.0, seed=0, polydispersity=0.0, mass=None):
    """n spheres on a jittered simple-cubic lattice in a cube at packing fraction
    ``packing`` (by mean volume), Gaussian velocities with rms component ``speed``
    [m/s] and zero total momentum. polydispersity: radii uniform in
    radius * [1 - p, 1]; mass None means density 1000 kg/m^3."""
    rng = np.random.default_rng(seed)
    radii = radius * (1.0 - polydispersity * rng.random(n)) if polydispersity else \
        np.full(n, float(radius))
    box = (np.sum(4.0 / 3.0 * math.pi * radii ** 3) / packing) ** (1.0 / 3.0)
    rmax = float(radii.max())
    side = int(math.floor(box / (2.0 * rmax)))
    if side ** 3 < n:
        raise ValueError(f"packing {packing} too dense for a simple-cubic start of {n} spheres "
                         f"(room for {side ** 3})")
    side = max(int(math.ceil(n ** (1.0 / 3.0) - 1e-9)), 1)
    while side ** 3 < n:
        side += 1
    spacing = box / side
    if spacing < 2.0 * rmax:     # rounding up n^(1/3) left too little room: use all sites
        side = int(math.floor(box / (2.0 * rmax)))
        spacing = box / side
    sites = (np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1)
             .reshape(-1, 3)[:n] + 0.5) * spacing
    jitter = 0.5 * (spacing - 2.0 * radii)[:, None] * (rng.random((n, 3)) * 2.0 - 1.0)
    x = sites + jitter
    v = rng.normal(scale=speed, size=(n, 3))
    if n > 1:
        v -= v.mean(axis=0)
    return Scene.from_arrays(x, v, radii, mass=mass, box=((0.0,) * 3, (box,) * 3),
                             periodic=(periodic,) * 3 if isinstance(periodic, bool) else periodic,
                             gravity=gravity, restitution=restitution,
                             wall_restitution=wall_restitution, name=f"gas{n}")


def same_bits_scene(n=400, frictional=False, materials=False, equal=False):
    """The reference scene of the same-bits promise (tests/test_same_bits.py,
    tools/state_digest.py): n spheres of radii 0.035-0.05 m and masses 0.5-2 kg on a
    jittered cubic lattice of spacing 0.125 m filling a cubic box (1 m for n <= 512),
    periodic in x and y, floor and ceiling walls, gravity -9.81 m/s^2 along z,
    restitution 0.8 (pairs) and 0.9 (walls), velocities uniform in [-2, 2] m/s.

    Built from IEEE-exact arithmetic only (lattice sums and products, uniform draws:
    no pow, exp or log, whose last bit may differ between C libraries), so that the
    scene itself has the same bits on every machine. frictional: also friction 0.4
    (walls too), tangential restitution 0.3, rolling friction 0.05, and a vertical post
    (a cylinder of radius 0.01 m, spheres outside) at the box's centre: the spin,
    Walton impacts, friction rows and geometry code paths. materials (with frictional):
    every other sphere of a second material (restitution 0.6, friction 0.2, no rolling
    friction): the per-pair table lookups. equal (without frictional): every sphere of
    radius 0.045 m and mass 1 kg, the equal-mass code paths of the contact solver
    (contacts/pgs.py push_halved) and its packed rows (contacts/packed.py)."""
    rng = np.random.default_rng(2024)
    side = 1
    while side ** 3 < n:
        side += 1
    spacing = 0.125
    idx = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), -1).reshape(-1, 3)[:n]
    radius = 0.05 - 0.015 * rng.random(n)
    jitter = (spacing - 2.0 * 0.05) * (rng.random((n, 3)) - 0.5)
    x = (idx + 0.5) * spacing + jitter
    v = 4.0 * rng.random((n, 3)) - 2.0
    mass = 0.5 + 1.5 * rng.random(n)
    if equal:
        radius, mass = np.full(n, 0.045), np.full(n, 1.0)
    extra = {}
    if frictional:
        centre = 0.5 * side * spacing
        extra = dict(friction=0.4, tangential_restitution=0.3, rolling_friction=0.05,
                     geometry=[Cylinder((centre, centre, 0.0), (0.0, 0.0, 1.0), 0.01,
                                        inside=False)])
        if materials:
            extra.update(materials=[Material("a"), Material("b", restitution=0.6, friction=0.2,
                                                            rolling_friction=0.0)],
                         material=np.arange(n) % 2)
    return Scene.from_arrays(x, v, radius, mass=mass, box=((0.0,) * 3, (side * spacing,) * 3),
                             periodic=(True, True, False), gravity=(0.0, 0.0, -9.81),
                             restitution=0.8, wall_restitution=0.9, name="same_bits", **extra)


def same_bits_case_scene(case: dict) -> Scene:
    """same_bits_scene of a case of tests/same_bits.json: its n and the flags it sets
    (frictional, materials, equal; absent: False)."""
    return same_bits_scene(case["n"], case.get("frictional", False),
                           case.get("materials", False), case.get("equal", False))


def fcc_block(cells=(5, 5, 10), radius=0.01, spacing=1.0 + 1e-6, restitution=0.5,
              gravity=9.81):
    """A face-centred cubic block of 4 cx cy cz equal spheres of ``radius`` [m] (``cells``:
    lattice cells per axis, an int for a cube; (5, 5, 10) gives 1,000), nearest
    neighbours ``spacing`` diameters apart, resting on the floor of a box that fits it
    on x and y (the layers sit in each other's hollows: stable without friction) and
    is 0.1 m taller, under gravity -``gravity`` [m/s^2] along z, with ``restitution``
    between spheres and on the walls."""
    cells = (cells,) * 3 if isinstance(cells, int) else tuple(cells)
    r = radius
    a = 2 * np.sqrt(2) * r * spacing
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    idx = np.array(np.meshgrid(*[np.arange(c) for c in cells], indexing="ij")).reshape(3, -1).T
    x = ((idx[:, None, :] + base[None]) * a).reshape(-1, 3) + r * (1 + 1e-6)
    side = [(c - 0.5) * a + 2 * r * (1 + 1e-6) for c in cells[:2]]
    return Scene.from_arrays(x, np.zeros_like(x), np.full(len(x), r),
                             box=((0, 0, 0), (side[0], side[1], cells[2] * a + 0.1)),
                             gravity=(0, 0, -gravity), restitution=restitution,
                             wall_restitution=restitution)


#: radius of box_pile's spheres [m]
PILE_RADIUS = 0.01


def box_pile(n_side=4, friction=0.5, rolling_friction=0.0, restitution=0.5, seed=3):
    """n_side^2 x 3 spheres of radius PILE_RADIUS dropped into a box they fill about 1.6
    layers deep: a jittered lattice (spacing 25 mm, up to 2 mm of horizontal jitter,
    layers at 20, 50 and 80 mm) with random velocities up to 0.2 m/s per component
    (``seed``), in a box n_side x 25 + 5 mm wide and 0.3 m tall; ``restitution``
    between spheres and on the walls, sliding and rolling ``friction``."""
    rng = np.random.default_rng(seed)
    g = np.arange(n_side) * 0.025 + 0.015
    x = np.array([(a, b, c) for a in g for b in g for c in (0.02, 0.05, 0.08)], float)
    x[:, :2] += rng.uniform(-2e-3, 2e-3, (len(x), 2))
    v = rng.uniform(-0.2, 0.2, x.shape)
    side = n_side * 0.025 + 0.005
    return Scene.from_arrays(x, v, PILE_RADIUS, box=((0, 0, 0), (side, side, 0.3)),
                             restitution=restitution, wall_restitution=restitution,
                             friction=friction, rolling_friction=rolling_friction)


def ball_on_block(block: Scene, settled, ratio=8.0, height=0.05, speed=1.0, offset=0.0,
                  side=0.0):
    """A ball ``ratio`` x heavier than the spheres of ``block`` (an :func:`fcc_block`,
    same radius; the block's friction and other settings kept) dropped onto it once
    settled: returns (scene, x, v) where the scene holds the lattice block and the
    ball ``height`` [m] above its top sphere's centre, ``offset`` [m] off its axis
    along x, and x, v (N + 1, 3) are ``settled`` (a State of the block) with the ball
    that height above the settled top, moving down at ``speed`` and along x at
    ``side`` [m/s], for ``Simulation.set_state`` (settled spheres touch to round-off,
    which a scene refuses)."""
    top = settled.x[:, 2].max()
    centre = [settled.x[:, 0].mean() + offset, settled.x[:, 1].mean()]
    mass = np.append(settled.mass, ratio * settled.mass[0])
    start = np.vstack([block.x, [[centre[0], centre[1], block.x[:, 2].max() + height]]])
    scene = block.replace(x=start, v=np.zeros_like(start),
                          radius=np.full(len(mass), block.radius[0]), mass=mass, omega=None,
                          material=None)
    x = np.vstack([settled.x, [[centre[0], centre[1], top + height]]])
    v = np.vstack([settled.v, [[side, 0.0, -speed]]])
    return scene, x, v
