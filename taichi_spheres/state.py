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

__all__ = ["Features", "SphereState", "State", "SPHERE_FIELDS", "copy_sphere", "has_field"]


#: what copy_sphere moves: the fields a sphere is made of (None where a scene
#: compiles them out), in SphereState and in takeout.StayerScratch alike
SPHERE_FIELDS = ("x", "v", "omega", "radius", "inv_mass", "inv_inertia", "material")


@ti.func
def copy_sphere(src: ti.template(), i, dst: ti.template(), j):
    """Sphere i of ``src`` to index j of ``dst`` (a SphereState or fields of the same
    names and shapes, takeout.StayerScratch): the SPHERE_FIELDS that ``src`` has."""
    for name in ti.static(SPHERE_FIELDS):
        if ti.static(has_field(src, name)):
            to, source = ti.static(getattr(dst, name), getattr(src, name))
            to[j] = source[i]


def has_field(obj, name: str) -> bool:
    """``obj`` has a field ``name`` (not None: a feature the scene compiles out)."""
    return getattr(obj, name, None) is not None


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
    contacts: bool = False   # contact solver for persistent contacts (inelastic pairs)
    friction: bool = False   # a friction coefficient is non-zero: spin field, tangential impulses
    rolling: bool = False    # rolling friction is non-zero (only with friction)
    geometry: bool = False   # static geometry besides the box (planes, cylinders, cones)
    sinks: bool = False      # regions that discharge spheres
    materials: bool = False  # pair values differ between materials: per-sphere index, table

    @classmethod
    def from_scene(cls, scene: Scene, rest_speed: float = 0.0) -> "Features":
        """rest_speed: the scene's floor of the impact speed [m/s]. The contact solver
        runs for inelastic pairs under gravity, or with a rest speed."""
        elastic = bool(getattr(scene, "elastic_pairs", scene.restitution == 1.0))
        friction = bool(getattr(scene, "frictional", False))
        return cls(gravity_axes=tuple(bool(g != 0.0) for g in scene.gravity),
                   wall_axes=tuple(not p for p in scene.periodic),
                   equal_radii=bool(np.all(scene.radius == scene.radius[0])),
                   equal_masses=bool(np.all(scene.mass == scene.mass[0])),
                   elastic=elastic,
                   elastic_walls=scene.wall_restitution == 1.0,
                   smid=not elastic and scene.restitution_model == "smid",
                   contacts=(not elastic or friction) and (any(g != 0.0 for g in scene.gravity)
                                                           or rest_speed > 0),
                   friction=friction,
                   rolling=friction and bool(getattr(scene, "rolling", False)),
                   geometry=len(getattr(scene, "geometry", ())) > 0,
                   sinks=len(getattr(scene, "sinks", ())) > 0,
                   materials=bool(getattr(scene, "varied_materials", False)))

    @property
    def gravity(self) -> bool:
        return any(self.gravity_axes)

    @property
    def walls(self) -> bool:
        return any(self.wall_axes)

    @property
    def periodic(self) -> bool:
        return not all(self.wall_axes)

    def describe(self, shock: bool = False) -> list:
        """Human-readable list of what is compiled in and out (``shock``: the contact
        solver's shock propagation pass, contacts/shock.py ``shock_compiled``)."""
        axes = "xyz"
        return [
            "gravity: " + (", ".join(a for a, g in zip(axes, self.gravity_axes) if g)
                           if self.gravity else "off (compiled out)"),
            "walls: " + (", ".join(a for a, w in zip(axes, self.wall_axes) if w)
                         if self.walls else "none (fully periodic, compiled out)"),
            "periodic axes: " + (", ".join(a for a, w in zip(axes, self.wall_axes) if not w)
                                 or "none"),
            "radii: " + ("equal (one number, no per-sphere field)" if self.equal_radii
                          else "per sphere"),
            "masses: " + ("equal (no mass field)" if self.equal_masses else "per sphere"),
            "pair restitution: " + ("1, elastic (compiled out)" if self.elastic else "inelastic"),
            "wall restitution: " + ("1, elastic (compiled out)" if self.elastic_walls
                                    else "inelastic"),
            "restitution model: " + ("smid" if self.smid else "normal"),
            "contact solver: " + ("on (persistent contacts, split impulse"
                                  + (", shock propagation)" if shock else ")")
                                  if self.contacts else "off (compiled out)"),
            "friction and spin: " + (("on, with rolling friction" if self.rolling else "on")
                                     if self.friction else "off (no spin field, compiled out)"),
            "geometry: " + ("planes, cylinders, cones" if self.geometry
                            else "box only (compiled out)"),
            "sinks: " + ("on" if self.sinks else "none (compiled out)"),
            "materials: " + ("per sphere (pair table)" if self.materials
                             else "one set of pair values (compiled out)"),
        ]


@dataclasses.dataclass(frozen=True)
class State:
    """Numpy copy of the simulation state at ``time`` (float64 whatever the precision).

    x, v: (N, 3) [m], [m/s]; radius, mass: (N,) [m], [kg]; time [s]; omega: (N, 3)
    angular velocity [rad/s] (zeros in a scene without friction).
    """

    x: np.ndarray
    v: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    time: float
    omega: np.ndarray = None

    def __post_init__(self):
        if self.omega is None:
            object.__setattr__(self, "omega", np.zeros_like(self.v))


@ti.data_oriented
class SphereState:
    """Positions, velocities and per-sphere bookkeeping, one field per quantity (SoA).

    Fields hold up to ``capacity`` spheres (so that Simulations of other sphere counts
    can run on the same fields and compiled kernels: see engine.py); the scene bound
    last (:meth:`bind`) uses the first n_spheres[None] of them.

    Fields (N = capacity, real = f32 or f64):
        x, v: (N,) vec3 real — centre [m] and velocity [m/s]
        radius: (N,) real, only without equal radii [m]
        inv_mass: (N,) real, only without equal masses [1/kg]
        moved: (N,) real — bound on the distance moved since the grid was built [m]
        hits: (N,) i32 — pair and wall collisions in the current step
        loaded: (N,) i32, only with features.contacts — 1 when a contact row of the
            sphere carried an impulse in the last step (contacts/solver.py)
        near: (N,) i32, only with features.contacts — with Rules.substeps, 1 when the
            sphere had a contact row to a wall, an object or a loaded sphere (or was
            loaded) at the last solve (ContactSolver.mark_near; stepping.py)
        omega: (N,) vec3 real, only with features.friction — angular velocity [rad/s]
        material: (N,) i32, only with features.materials — material index (materials.py)
        inv_inertia: (N,) real, only with features.friction and radii or masses that
            differ — 1/I of each sphere [1/(kg m^2)] (set where masses load)
        n_spheres: () i32 — spheres of the bound scene
        r0, m0: () real — the radius [m] and mass [kg] of every sphere when equal
        inv_m0, inv_i0: () real — 1/m0 [1/kg] and, with friction, 1/I of a sphere of
            radius r0 and mass m0 [1/(kg m^2)]: kept, not divided in each row update
    """

    def __init__(self, capacity: int, features: Features, real):
        self.capacity = capacity
        self.n = 0
        self.real = real
        self.features = features
        self.x = ti.Vector.field(3, real, shape=capacity)
        self.v = ti.Vector.field(3, real, shape=capacity)
        self.radius = None if features.equal_radii else ti.field(real, shape=capacity)
        self.inv_mass = None if features.equal_masses else ti.field(real, shape=capacity)
        self.moved = ti.field(real, shape=capacity)
        self.hits = ti.field(ti.i32, shape=capacity)
        self.loaded = ti.field(ti.i32, shape=capacity) if features.contacts else None
        self.near = ti.field(ti.i32, shape=capacity) if features.contacts else None
        self.omega = ti.Vector.field(3, real, shape=capacity) if features.friction else None
        self.material = ti.field(ti.i32, shape=capacity) if features.materials else None
        self.per_sphere_inertia = features.friction and not (features.equal_radii
                                                             and features.equal_masses)
        self.inv_inertia = (ti.field(real, shape=capacity) if self.per_sphere_inertia
                            else None)
        self.n_spheres = ti.field(ti.i32, shape=())
        self.r0 = ti.field(real, shape=())
        self.m0 = ti.field(real, shape=())
        self.inv_m0 = ti.field(real, shape=())
        self.inv_i0 = ti.field(real, shape=())
        self.host_load = None      # the engine's hostload.FieldLoad
        np_real = np.float64 if real == ti.f64 else np.float32

        @ti.kernel
        def load_rows(x: ti.types.ndarray(dtype=real, ndim=2),
                      v: ti.types.ndarray(dtype=real, ndim=2),
                      radius: ti.types.ndarray(dtype=real, ndim=1),
                      inv_mass: ti.types.ndarray(dtype=real, ndim=1),
                      omega: ti.types.ndarray(dtype=real, ndim=2)):
            for i in range(self.n_spheres[None]):
                for a in ti.static(range(3)):
                    self.x[i][a] = x[i, a]
                    self.v[i][a] = v[i, a]
                    if ti.static(features.friction):
                        self.omega[i][a] = omega[i, a]
                if ti.static(not features.equal_radii):
                    self.radius[i] = radius[i]
                if ti.static(not features.equal_masses):
                    self.inv_mass[i] = inv_mass[i]
                if ti.static(self.per_sphere_inertia):
                    self.inv_inertia[i] = self.solid_inv_inertia(self.mass_of(i), self.rad(i))

        @ti.kernel
        def read_rows(x: ti.types.ndarray(dtype=real, ndim=2),
                      v: ti.types.ndarray(dtype=real, ndim=2),
                      omega: ti.types.ndarray(dtype=real, ndim=2)):
            for i in range(self.n_spheres[None]):
                for a in ti.static(range(3)):
                    x[i, a] = self.x[i][a]
                    v[i, a] = self.v[i][a]
                    if ti.static(features.friction):
                        omega[i, a] = self.omega[i][a]

        self._np_real = np_real
        self._load_rows = load_rows
        self._read_rows = read_rows

    def bind(self, scene: Scene, x, v, omega=None):
        """Make ``scene`` (at most ``capacity`` spheres) the one the fields hold: its
        sphere count, equal radius and mass, radii and masses, and the positions x [m],
        velocities v [m/s] and spins omega [rad/s] ((n, 3) each; None: zero)."""
        if scene.n > self.capacity:
            raise ValueError(f"{scene.n} spheres do not fit fields for {self.capacity}")
        self.n = scene.n
        self.bind_uniform(scene)
        self.load(x, v, scene.radius, scene.mass, omega)
        if self.features.materials:
            index = np.zeros(self.capacity, dtype=np.int32)
            index[:scene.n] = scene.material
            self.material.from_numpy(index)

    def bind_uniform(self, scene: Scene):
        """n_spheres = scene.n; r0, m0 [m, kg]: the radius and mass of the scene's first
        sphere (those of every sphere where they are equal), and their inverses
        (set_count_and_inverses)."""
        self.host_load.write(self, r0=float(scene.radius[0]), m0=float(scene.mass[0]))
        self.set_count_and_inverses(scene.n)

    @staticmethod
    def loaded_fields() -> tuple:
        """The fields bind loads (hostload.FieldLoad; n_spheres, which a take-out
        changes in a kernel, is set_count_and_inverses')."""
        return ("r0", "m0")

    @ti.kernel
    def set_count_and_inverses(self, n: ti.i32):
        """n_spheres = n; inv_m0 = 1/m0 and inv_i0 = 1/I(m0, r0), in the fields'
        precision, as a row update would divide them (same bits)."""
        self.n_spheres[None] = n
        self.inv_m0[None] = 1 / self.m0[None]
        self.inv_i0[None] = self.solid_inv_inertia(self.m0[None], self.r0[None])

    @ti.func
    def solid_inv_inertia(self, m, r):
        """1/I of a solid sphere of mass m [kg] and radius r [m], I = 2/5 m r^2."""
        return ti.cast(2.5, self.real) / (m * r * r)

    def load(self, x, v, radius, mass, omega=None):
        """Positions [m], velocities [m/s], radii [m], masses [kg] and spins [rad/s] (None:
        zero) of the bound scene's spheres ((n, 3), (n, 3), (n,), (n,), (n, 3))."""
        real = self._np_real
        if omega is None:
            omega = np.zeros((len(mass), 3))
        self._load_rows(np.ascontiguousarray(x, dtype=real), np.ascontiguousarray(v, dtype=real),
                        np.ascontiguousarray(radius, dtype=real),
                        np.ascontiguousarray(1.0 / np.asarray(mass, dtype=np.float64), dtype=real),
                        np.ascontiguousarray(omega, dtype=real))

    def _rows(self):
        x = np.empty((self.n, 3), dtype=self._np_real)
        v = np.empty((self.n, 3), dtype=self._np_real)
        omega = np.zeros((self.n, 3), dtype=self._np_real)
        self._read_rows(x, v, omega)
        return x, v, omega

    def positions(self) -> np.ndarray:
        """(n, 3) float64 copy of the bound scene's positions [m]."""
        return self._rows()[0].astype(np.float64)

    def velocities(self) -> np.ndarray:
        """(n, 3) float64 copy of the bound scene's velocities [m/s]."""
        return self._rows()[1].astype(np.float64)

    def spins(self) -> np.ndarray:
        """(n, 3) float64 copy of the bound scene's angular velocities [rad/s] (zeros
        without friction)."""
        return self._rows()[2].astype(np.float64)

    def rows(self):
        """(x, v, omega) of the bound scene in the field precision, (n, 3) each."""
        return self._rows()

    @ti.func
    def move_sphere(self, i, j):
        """Sphere i's position, velocity, spin, radius, inverse mass and inertia and
        material to index j (the per-step bookkeeping, moved and hits, stays)."""
        copy_sphere(self, i, self, j)

    @ti.func
    def rad(self, i):
        """Radius of sphere i [m] (one scalar when all radii are equal)."""
        r = self.r0[None]
        if ti.static(not self.features.equal_radii):
            r = self.radius[i]
        return r

    @ti.func
    def material_of(self, i):
        """Material index of sphere i (0 when the scene's pair values are one set)."""
        out = 0
        if ti.static(self.features.materials):
            out = self.material[i]
        return out

    @ti.func
    def inv_mass_of(self, i):
        """1/m of sphere i [1/kg]; only called when masses differ."""
        return self.inv_mass[i]

    @ti.func
    def inv_inertia_of(self, i):
        """1/I of sphere i, I = 2/5 m r^2 (solid sphere) [1/(kg m^2)]; kept, not
        divided (inv_i0 when radii and masses are equal)."""
        out = self.inv_i0[None]
        if ti.static(self.per_sphere_inertia):
            out = self.inv_inertia[i]
        return out

    @ti.func
    def spin(self, i):
        """Angular velocity of sphere i [rad/s] (zero without friction)."""
        out = ti.Vector.zero(self.real, 3)
        if ti.static(self.features.friction):
            out = self.omega[i]
        return out

    @ti.func
    def mass_of(self, i):
        """Mass of sphere i [kg] (one scalar when all masses are equal)."""
        m = self.m0[None]
        if ti.static(not self.features.equal_masses):
            m = 1 / self.inv_mass[i]
        return m
