"""Ready-made scenes for tests, benchmarks and examples (numpy only, reproducible)."""
from __future__ import annotations

import math

import numpy as np

from .geometry import Cylinder
from .materials import Material
from .scene import Scene

__all__ = ["gas", "same_bits_scene"]


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


def same_bits_scene(n=400, frictional=False, materials=False):
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
    friction): the per-pair table lookups."""
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
