"""State: per-sphere SoA fields on the Taichi device (stage 2 of the data flow).

Features a scene does not need are not allocated: equal radii keep one number
instead of a radius field, equal masses keep no mass field at all (the collision
update then uses weights 1/2), and every kernel reads radii and inverse masses
through :meth:`SphereState.rad` / :meth:`SphereState.inv_mass_of`, which compile
to constants in that case.
"""

import dataclasses

import numpy as np
import taichi as ti

from .scene import Scene

__all__ = ["Features", "SphereState", "State"]


@dataclasses.dataclass(frozen=True)
class Features:
    """What a scene needs compiled in; everything False/empty is compiled out."""

    gravity_axes: tuple      # per axis: gravity component != 0
    wall_axes: tuple         # per axis: walls (True) or periodic (False)
    equal_radii: bool
    equal_masses: bool
    elastic: bool            # pair restitution == 1
    elastic_walls: bool      # wall restitution == 1
    smid: bool = False       # pair restitution model "smid" (only with elastic False)
    rest_rule: bool = False  # e = 0 below the rest speed (only with elastic False)

    @classmethod
    def from_scene(cls, scene: Scene, rest_speed: float = 0.0) -> "Features":
        """rest_speed: the resolved rest speed [m/s] (0 turns the rule off)."""
        elastic = scene.restitution == 1.0
        return cls(gravity_axes=tuple(bool(g != 0.0) for g in scene.gravity),
                   wall_axes=tuple(not p for p in scene.periodic),
                   equal_radii=bool(np.all(scene.radius == scene.radius[0])),
                   equal_masses=bool(np.all(scene.mass == scene.mass[0])),
                   elastic=elastic,
                   elastic_walls=scene.wall_restitution == 1.0,
                   smid=not elastic and scene.restitution_model == "smid",
                   rest_rule=not elastic and rest_speed > 0)

    @property
    def supports(self) -> bool:
        """Slow contacts on top of supported spheres (floor or a supported sphere
        below) treat the lower sphere as immovable: needs gravity and the rest rule."""
        return self.gravity and self.rest_rule

    @property
    def gravity(self) -> bool:
        return any(self.gravity_axes)

    @property
    def walls(self) -> bool:
        return any(self.wall_axes)

    @property
    def periodic(self) -> bool:
        return not all(self.wall_axes)

    def describe(self) -> list:
        """Human-readable list of what is compiled in and out."""
        axes = "xyz"
        return [
            "gravity: " + (", ".join(a for a, g in zip(axes, self.gravity_axes) if g)
                           if self.gravity else "off (compiled out)"),
            "walls: " + (", ".join(a for a, w in zip(axes, self.wall_axes) if w)
                         if self.walls else "none (fully periodic, compiled out)"),
            "periodic axes: " + (", ".join(a for a, w in zip(axes, self.wall_axes) if not w)
                                 or "none"),
            "radii: " + ("equal (constant, no field)" if self.equal_radii else "per sphere"),
            "masses: " + ("equal (no mass field)" if self.equal_masses else "per sphere"),
            "pair restitution: " + ("1, elastic (compiled out)" if self.elastic else "inelastic"),
            "wall restitution: " + ("1, elastic (compiled out)" if self.elastic_walls
                                    else "inelastic"),
            "restitution model: " + ("smid" if self.smid else "normal"),
            "rest rule: " + ("on" + (", with supports" if self.supports else "")
                             if self.rest_rule else "off (compiled out)"),
        ]


@dataclasses.dataclass(frozen=True)
class State:
    """Numpy copy of the simulation state at ``time`` (float64 whatever the precision).

    x, v: (N, 3) [m], [m/s]; radius, mass: (N,) [m], [kg]; time [s].
    """

    x: np.ndarray
    v: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    time: float


@ti.data_oriented
class SphereState:
    """Positions, velocities and per-sphere bookkeeping, one field per quantity (SoA).

    Fields (N = number of spheres, real = f32 or f64):
        x, v: (N,) vec3 real — centre [m] and velocity [m/s]
        radius: (N,) real, only without equal radii [m]
        inv_mass: (N,) real, only without equal masses [1/kg]
        moved: (N,) real — bound on the distance moved since the grid was built [m]
        hits: (N,) i32 — pair and wall collisions in the current step
        support: (N,) i32, only with features.supports — 1 when the sphere rests on
            the floor or on a supported sphere in the current step
    """

    def __init__(self, scene: Scene, features: Features, real):
        n = scene.n
        self.n = n
        self.real = real
        self.features = features
        self.r0 = float(scene.radius[0])
        self.r_max = float(scene.radius.max())
        self.m0 = float(scene.mass[0])
        self.box_lo = tuple(float(c) for c in scene.box_lo)
        self.box_hi = tuple(float(c) for c in scene.box_hi)
        self.x = ti.Vector.field(3, real, shape=n)
        self.v = ti.Vector.field(3, real, shape=n)
        self.radius = None if features.equal_radii else ti.field(real, shape=n)
        self.inv_mass = None if features.equal_masses else ti.field(real, shape=n)
        self.moved = ti.field(real, shape=n)
        self.hits = ti.field(ti.i32, shape=n)
        self.support = ti.field(ti.i32, shape=n) if features.supports else None
        self.load(scene.x, scene.v, scene.radius, scene.mass)

    def load(self, x, v, radius, mass):
        np_real = np.float64 if self.real == ti.f64 else np.float32
        self.x.from_numpy(np.ascontiguousarray(x, dtype=np_real))
        self.v.from_numpy(np.ascontiguousarray(v, dtype=np_real))
        if self.radius is not None:
            self.radius.from_numpy(np.ascontiguousarray(radius, dtype=np_real))
        if self.inv_mass is not None:
            self.inv_mass.from_numpy(np.ascontiguousarray(1.0 / mass, dtype=np_real))

    def positions(self) -> np.ndarray:
        return self.x.to_numpy().astype(np.float64)

    def velocities(self) -> np.ndarray:
        return self.v.to_numpy().astype(np.float64)

    @ti.func
    def rad(self, i):
        """Radius of sphere i [m] (a constant when all radii are equal)."""
        r = ti.cast(ti.static(self.r0), self.real)
        if ti.static(not self.features.equal_radii):
            r = self.radius[i]
        return r

    @ti.func
    def inv_mass_of(self, i):
        """1/m of sphere i [1/kg]; only called when masses differ."""
        return self.inv_mass[i]

    @ti.func
    def mass_of(self, i):
        """Mass of sphere i [kg] (a constant when all masses are equal)."""
        m = ti.cast(ti.static(self.m0), self.real)
        if ti.static(not self.features.equal_masses):
            m = 1 / self.inv_mass[i]
        return m
