"""Scene: validated initial conditions and physical parameters (stage 1 of the data flow).

A :class:`Scene` is plain numpy data (SI units, z up, positions are sphere centres).
It never touches Taichi, so it can be built, checked and saved before ``ti.init``.
Bad input raises ``ValueError`` naming the offending sphere index or argument;
nothing is silently fixed.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import geometry as geo
from . import materials as mat

__all__ = ["Scene", "DEFAULT_DENSITY", "TOUCH_TOLERANCE", "RESTITUTION_MODELS", "MIN_STEP_ULPS",
           "OVERFLOW_HEADROOM", "largest_speed", "smallest_radius", "fall_speed",
           "speed_problem", "radius_problem", "mass_problem", "gravity_problem",
           "vector_text", "check_state", "FRICTION_RANGES", "PERIODIC_SLACK",
           "scene_precision_problems", "spin_problem"]

#: Simulation.set_state accepts a centre this far outside a periodic axis's [lo, hi),
#: relative to the largest of |lo|, |hi| and the box's extent: the engine's wrap x +- L
#: in f32 can round onto hi or an ulp below lo, and its next step wraps it back.
PERIODIC_SLACK = 4.0 * 2.0 ** -23
#: (low, high) of each friction coefficient of a scene (high inf: finite).
FRICTION_RANGES = {"friction": (0.0, math.inf), "wall_friction": (0.0, math.inf),
                   "tangential_restitution": (-1.0, 1.0), "rolling_friction": (0.0, math.inf)}
#: Pair restitution models: "normal" (default) and "smid" (the seed's rule).
RESTITUTION_MODELS = ("normal", "smid")

#: kg/m^3, used when neither ``mass`` nor ``density`` is given (water).
DEFAULT_DENSITY = 1000.0
#: Relative overlap allowed at set-up so that spheres given as exactly touching
#: (distance == r_i + r_j, or centre +- radius == wall, up to decimal round-off)
#: are accepted.
TOUCH_TOLERANCE = 1e-10
#: A step moves a sphere at most step_fraction x the smallest radius; that move must span
#: at least this many units in the last place (ulps) of the largest coordinate in the box,
#: in the simulation's precision. Below it positions cannot record the motion: each
#: step's move would round by more than 1 / (2 x MIN_STEP_ULPS) = 6 %, and a radius
#: under one ulp would not move at all (the run would never end).
MIN_STEP_ULPS = 8
#: Speeds are squared (kinetic energy, the step bound, the contact-time quadratics) and
#: summed in pairs: a speed must stay below sqrt(largest float) / OVERFLOW_HEADROOM of the
#: precision (f64: 8.4e152 m/s, f32: 1.2e18 m/s), a mass within its range / HEADROOM^2.
OVERFLOW_HEADROOM = 16.0
#: numpy dtype of each precision name.
PRECISION_DTYPES = {"f32": np.float32, "f64": np.float64}


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """Initial state and physics of a hard-sphere system.

    Attributes (all float64 numpy arrays unless noted):
        x: (N, 3) centres [m];  v: (N, 3) velocities [m/s]
        radius: (N,) [m];  mass: (N,) [kg]
        box_lo, box_hi: (3,) box corners [m];  periodic: tuple of 3 bools
        gravity: (3,) [m/s^2];  restitution: pair e;  wall_restitution: wall e
        restitution_model: "normal" (u_n' = -e u_n, tangential unchanged) or "smid"
            (the seed's rule after Smid 2007: the whole relative velocity of the
            elastic result is scaled by e about the centre of mass)
        rest_speed: approach speed [m/s] below which a pair collision is perfectly
            inelastic (e = 0; only with e < 1); None = automatic (see Simulation)
        name: free text used in output file names and logs.
        friction, wall_friction: Coulomb coefficients mu >= 0 of pairs and of the box's
            walls; tangential_restitution: Walton's beta0 in [-1, 1] (-1: Coulomb
            friction without tangential elasticity; contacts/friction.py);
            rolling_friction: mu_r >= 0 (rolling torque <= mu_r r_eff x normal force)
        omega: (N, 3) angular velocities [rad/s] (zeros unless given)
        geometry: tuple of ts.Plane / ts.Cylinder / ts.Cone (geometry.py), their
            restitution and friction resolved; sinks: tuple of ts.Sink
        material: (N,) int32 index of each sphere's material; materials: tuple of
            ts.Material as given (None coefficients: the scene's values; empty: one
            material of the scene's values); material_pairs: {(a, b): ts.Material}
            overrides, a <= b (materials.py: pair values are the smaller of the two
            materials'; :meth:`pair_values` gives the table)
    """

    x: np.ndarray
    v: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    periodic: tuple
    gravity: np.ndarray
    restitution: float = 1.0
    wall_restitution: float = 1.0
    restitution_model: str = "normal"
    rest_speed: float | None = None
    name: str = "scene"
    #: settings read from a scene file that are not physics ([run], [physics] extras)
    meta: dict = dataclasses.field(default_factory=dict)
    friction: float = 0.0
    wall_friction: float = 0.0
    tangential_restitution: float = -1.0
    rolling_friction: float = 0.0
    omega: np.ndarray = None
    geometry: tuple = ()
    sinks: tuple = ()
    material: np.ndarray = None
    materials: tuple = ()
    material_pairs: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.omega is None:
            object.__setattr__(self, "omega", np.zeros_like(self.v))
        if self.material is None:
            object.__setattr__(self, "material", np.zeros(self.n, dtype=np.int32))
        defaults = dict(restitution=self.restitution, friction=self.friction,
                        rolling_friction=self.rolling_friction)
        table = mat.pair_table(mat.resolved(self.materials, defaults), self.material_pairs)
        table.setflags(write=False)
        object.__setattr__(self, "_pair_values", table)

    def pair_values(self) -> np.ndarray:
        """(M, M, 3) restitution, friction and rolling friction of each pair of the M
        materials (materials.pair_table; read-only)."""
        return self._pair_values

    def used_pair_values(self) -> np.ndarray:
        """The rows and columns of :meth:`pair_values` of the materials spheres use."""
        used = np.unique(self.material)
        return self.pair_values()[np.ix_(used, used)]

    @property
    def varied_materials(self) -> bool:
        """True when pairs of spheres in this scene have different pair values (the
        engine then looks them up per pair)."""
        table = self.used_pair_values()
        return bool(np.any(table != table[0, 0]))

    @property
    def elastic_pairs(self) -> bool:
        """True when every pair of materials the spheres use has restitution 1."""
        return bool(np.all(self.used_pair_values()[..., 0] == 1.0))

    @property
    def frictional(self) -> bool:
        """True when a friction coefficient (pairs, walls, geometry, rolling, materials)
        is not 0: the engine then simulates spin."""
        table = self.pair_values()[..., 1:]
        return bool(self.friction or self.wall_friction or self.rolling_friction
                    or any(g.friction for g in self.geometry) or np.any(table > 0))

    @property
    def rolling(self) -> bool:
        """True when a rolling friction (the scene's or a material's) is not 0."""
        return bool(self.rolling_friction or np.any(self.pair_values()[..., 2] > 0))

    @property
    def n(self) -> int:
        """Number of spheres."""
        return int(self.x.shape[0])

    @property
    def box_size(self) -> np.ndarray:
        return self.box_hi - self.box_lo

    @classmethod
    def from_arrays(cls, x, v, radius, mass=None, density=None,
                    box=((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), periodic=(False, False, False),
                    gravity=(0.0, 0.0, -9.81), restitution=1.0, wall_restitution=1.0,
                    name="scene", restitution_model="normal", rest_speed=None,
                    friction=0.0, wall_friction=None, tangential_restitution=-1.0,
                    rolling_friction=0.0, omega=None, geometry=(), sinks=(),
                    material=None, materials=(), material_pairs=None) -> "Scene":
        """Build and validate a scene from arrays.

        x, v: (N, 3) positions [m] and velocities [m/s]. radius: scalar or (N,) [m].
        mass: scalar or (N,) [kg], or density: scalar or (N,) [kg/m^3] (mass = density
        * 4/3 pi r^3); give at most one of them, neither means density 1000 kg/m^3.
        box: ((xlo, ylo, zlo), (xhi, yhi, zhi)); periodic: per-axis bools.
        restitution_model: "normal" or "smid"; rest_speed: None or >= 0 [m/s]
        (see the class docstring). friction >= 0, wall_friction (None: = friction),
        tangential_restitution in [-1, 1], rolling_friction >= 0; omega: (N, 3) [rad/s]
        or None (zero spin); geometry: ts.Plane / ts.Cylinder / ts.Cone objects (their
        restitution and friction None: the wall values); sinks: ts.Sink regions.
        materials: ts.Material objects (their None coefficients: the scene's values),
        material: each sphere's index into them ((N,) ints or one int; None: 0),
        material_pairs: {(a, b): ts.Material} pair values instead of the smaller of the
        two materials' (materials.py).
        Raises ValueError naming the argument or sphere index at fault.
        """
        x, v, radius = _spheres(x, v, radius)
        lo, hi = _box(box)
        periodic = _periodic(periodic)
        _raise_first([speed_problem("f64", v), radius_problem("f64", radius, lo, hi)])
        mass = _masses(mass, density, radius)
        _raise_first([mass_problem("f64", mass)])
        gravity = _vector3("gravity", gravity)
        _raise_first([gravity_problem("f64", gravity, fall_speed(gravity, lo, hi))])
        restitution = _restitution("restitution", restitution)
        wall_restitution = _restitution("wall_restitution", wall_restitution)
        if restitution_model not in RESTITUTION_MODELS:
            raise ValueError(f"restitution_model must be one of {RESTITUTION_MODELS}, "
                             f"got {restitution_model!r}")
        rest_speed = _rest_speed(rest_speed)
        _inside_box(x, radius, lo, hi, periodic)
        _no_overlaps(x, radius, lo, hi, periodic)
        spin = _friction(friction, wall_friction, tangential_restitution, rolling_friction)
        spin["omega"] = _omega(omega, x.shape[0], radius)
        shapes = _geometry(geometry, sinks, wall_restitution, spin["wall_friction"], x, radius,
                           lo, hi)
        kinds = _materials(material, materials, material_pairs, x.shape[0])
        scene = cls(x=x, v=v, radius=radius, mass=mass, box_lo=lo, box_hi=hi,
                    periodic=periodic, gravity=gravity, restitution=restitution,
                    wall_restitution=wall_restitution, restitution_model=restitution_model,
                    rest_speed=rest_speed, name=str(name), **spin, **shapes, **kinds)
        if scene.frictional and restitution_model == "smid":
            raise ValueError("restitution_model 'smid' has no tangential model: use "
                             "'normal' with friction")
        problem = spin_problem(scene.omega, scene.frictional)
        if problem:
            raise ValueError(problem)
        return scene

    def replace(self, **changes) -> "Scene":
        """A validated copy with some arguments of :meth:`from_arrays` changed."""
        args = dict(x=self.x, v=self.v, radius=self.radius, mass=self.mass,
                    box=(self.box_lo, self.box_hi), periodic=self.periodic,
                    gravity=self.gravity, restitution=self.restitution,
                    wall_restitution=self.wall_restitution, name=self.name,
                    restitution_model=self.restitution_model, rest_speed=self.rest_speed,
                    friction=self.friction, wall_friction=self.wall_friction,
                    tangential_restitution=self.tangential_restitution,
                    rolling_friction=self.rolling_friction, omega=self.omega,
                    geometry=self.geometry, sinks=self.sinks, material=self.material,
                    materials=self.materials, material_pairs=self.material_pairs)
        if "density" in changes:
            args.pop("mass")
        args.update(changes)
        return dataclasses.replace(Scene.from_arrays(**args), meta=dict(self.meta))


def _spheres(x, v, radius):
    """Checked (N, 3) positions [m], (N, 3) velocities [m/s] and (N,) radii [m]."""
    x = _array("x", x, ndim=2)
    n = x.shape[0]
    if x.shape[1:] != (3,):
        raise ValueError(f"x must have shape (N, 3), got {x.shape}")
    if n == 0:
        raise ValueError("x: a scene needs at least one sphere")
    v = _array("v", v, ndim=2)
    if v.shape != (n, 3):
        raise ValueError(f"v must have shape ({n}, 3) like x, got {v.shape}")
    radius = _per_sphere("radius", radius, n)
    _finite_rows("x", x)
    _finite_rows("v", v)
    _positive("radius", radius)
    return x, v, radius


def _box(box):
    """Checked lower and upper box corners [m] from ((xlo, ylo, zlo), (xhi, yhi, zhi))."""
    try:
        lo, hi = box
    except (TypeError, ValueError):
        raise ValueError("box must be ((xlo, ylo, zlo), (xhi, yhi, zhi))") from None
    lo = _vector3("box lower corner", lo)
    hi = _vector3("box upper corner", hi)
    for a in range(3):
        if not hi[a] > lo[a]:
            raise ValueError(f"box: upper corner must exceed lower corner on axis {'xyz'[a]} "
                             f"({lo[a]} .. {hi[a]})")
    with np.errstate(over="ignore"):
        if not np.isfinite(hi - lo).all():
            raise ValueError(f"box: size {(hi - lo).tolist()} is not finite")
    return lo, hi


def _masses(mass, density, radius):
    """(N,) masses [kg] from mass [kg] or density [kg/m^3] (default DEFAULT_DENSITY)."""
    n = radius.shape[0]
    if mass is not None and density is not None:
        raise ValueError("give either mass or density, not both")
    if mass is not None:
        mass = _per_sphere("mass", mass, n)
        _positive("mass", mass)
        return mass
    dens = _per_sphere("density", DEFAULT_DENSITY if density is None else density, n)
    _positive("density", dens)
    with np.errstate(over="ignore", under="ignore"):
        mass = dens * (4.0 / 3.0) * math.pi * radius ** 3
    _positive("mass (from density)", mass)
    bad = np.flatnonzero(~np.isfinite(mass))
    if bad.size:
        raise ValueError(f"mass (from density) of sphere {bad[0]} is not finite "
                         f"(density {dens[bad[0]]}, radius {radius[bad[0]]})" + _more(bad))
    return mass


def _rest_speed(rest_speed):
    """None (automatic) or a finite rest speed >= 0 [m/s]."""
    if rest_speed is None:
        return None
    try:
        rest_speed = float(rest_speed)
    except (TypeError, ValueError):
        raise ValueError(f"rest_speed must be a number >= 0 or None, got {rest_speed!r}") from None
    if not (math.isfinite(rest_speed) and rest_speed >= 0):
        raise ValueError(f"rest_speed must be a finite number >= 0, got {rest_speed}")
    return rest_speed


def _coefficient(name, value, low=0.0, high=math.inf) -> float:
    """A finite number in [low, high], else ValueError naming it."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (low <= out <= high) or not math.isfinite(out):
        limit = f"in [{low:g}, {high:g}]" if math.isfinite(high) else f">= {low:g} and finite"
        raise ValueError(f"{name} must be {limit}, got {value!r}")
    return out


def _friction(friction, wall_friction, beta0, rolling) -> dict:
    """Checked friction, wall_friction (None: = friction), tangential_restitution and
    rolling_friction (FRICTION_RANGES)."""
    mu = _coefficient("friction", friction, *FRICTION_RANGES["friction"])
    return dict(friction=mu,
                wall_friction=mu if wall_friction is None else
                _coefficient("wall_friction", wall_friction, *FRICTION_RANGES["wall_friction"]),
                tangential_restitution=_coefficient(
                    "tangential_restitution", beta0, *FRICTION_RANGES["tangential_restitution"]),
                rolling_friction=_coefficient("rolling_friction", rolling,
                                              *FRICTION_RANGES["rolling_friction"]))


def _materials(material, materials, pairs, n) -> dict:
    """Checked per-sphere material indices, materials (as given: Scene resolves and
    checks them) and pair overrides."""
    materials = tuple(materials or ())
    count = max(len(materials), 1)
    return dict(material=mat.material_indices(material, n, count), materials=materials,
                material_pairs=mat.resolved_pairs(pairs, count))


def _omega(omega, n, radius) -> np.ndarray:
    """(n, 3) angular velocities [rad/s] (zeros for None), finite, their surface speed
    |omega| r within what f64 holds."""
    if omega is None:
        return np.zeros((n, 3))
    omega = _array("omega", omega, ndim=2)
    if omega.shape != (n, 3):
        raise ValueError(f"omega must have shape ({n}, 3) like x, got {omega.shape}")
    _finite_rows("omega", omega)
    problem = speed_problem("f64", omega * radius[:, None])
    if problem:
        raise ValueError("omega: surface " + problem)
    return omega


def _geometry(geometry, sinks, wall_restitution, wall_friction, x, radius, lo, hi) -> dict:
    """Checked geometry (materials resolved, no sphere inside, orifices within the box)
    and sinks."""
    shapes = geo.resolved(() if geometry is None else geometry, wall_restitution,
                          wall_friction)
    problems = [geo.hole_problem(k, g, lo, hi) for k, g in enumerate(shapes)
                if isinstance(g, geo.Plane)]
    _raise_first(problems + [geo.inside_problem(x, radius, shapes, TOUCH_TOLERANCE)])
    return dict(geometry=shapes, sinks=geo.check_sinks(() if sinks is None else sinks, lo, hi))


def _raise_first(problems):
    for problem in problems:
        if problem:
            raise ValueError(problem)


# ------------------------------------------------------------- what a precision can hold

def largest_speed(precision: str) -> float:
    """The largest speed [m/s] a simulation in ``precision`` ("f32" | "f64") can hold:
    sqrt(largest float) / OVERFLOW_HEADROOM."""
    return math.sqrt(float(np.finfo(PRECISION_DTYPES[precision]).max)) / OVERFLOW_HEADROOM


def smallest_radius(precision: str, lo, hi, step_fraction: float = 1.0) -> float:
    """The smallest radius [m] a simulation in ``precision`` can move in the box [lo, hi]
    [m]: a step's largest move, step_fraction x radius, spans MIN_STEP_ULPS units in the
    last place of the largest coordinate."""
    extent = float(np.max(np.abs(np.concatenate([np.ravel(lo), np.ravel(hi)]))))
    dtype = PRECISION_DTYPES[precision]
    ulp = float(np.spacing(dtype(extent))) if extent > 0 else float(np.finfo(dtype).tiny)
    return MIN_STEP_ULPS * ulp / step_fraction


def vector_text(values) -> str:
    """Three numbers as "[0, 0, -9.81]"."""
    return f"[{', '.join(f'{float(c):g}' for c in values)}]"


def fall_speed(gravity, lo, hi) -> float:
    """Speed [m/s] gravity [m/s^2] gives a sphere falling across the box [lo, hi] [m]
    along every axis: sqrt(2 sum_a |g_a| (hi_a - lo_a))."""
    with np.errstate(over="ignore"):
        drop = float(np.sum(np.abs(gravity) * (np.asarray(hi) - np.asarray(lo))))
        return math.sqrt(2.0 * drop) if math.isfinite(drop) else math.inf


def speed_problem(precision: str, v) -> str | None:
    """Why the fastest sphere of (N, 3) velocities v [m/s] overflows ``precision``, or None."""
    speed = np.sqrt(np.sum(np.square(v / largest_speed(precision)), axis=1))
    bad = np.flatnonzero(speed > 1.0)
    if not bad.size:
        return None
    i = int(bad[np.argmax(speed[bad])])
    return (f"speed of sphere {i} ({speed[i] * largest_speed(precision):.3g} m/s) overflows "
            f"{precision}: its square must stay finite, at most "
            f"{largest_speed(precision):.2g} m/s" + _more(bad))


def radius_problem(precision: str, radius, lo, hi, step_fraction: float = 1.0) -> str | None:
    """Why the smallest of the radii [m] is too small for ``precision`` in the box, or None."""
    least = smallest_radius(precision, lo, hi, step_fraction)
    bad = np.flatnonzero(radius < least)
    if not bad.size:
        return None
    j = int(bad[np.argmin(radius[bad])])
    return (f"radius of sphere {j} ({radius[j]:.3g} m) is below what {precision} can "
            f"simulate in this box (coordinates up to {np.max(np.abs([lo, hi])):g} m): a "
            f"step's move, step_fraction x radius, must span {MIN_STEP_ULPS} units in the "
            f"last place; smallest radius {least:.2g} m at step_fraction {step_fraction:g}"
            + _more(bad))


def mass_problem(precision: str, mass) -> str | None:
    """Why a mass [kg] underflows or overflows ``precision``, or None."""
    info = np.finfo(PRECISION_DTYPES[precision])
    low, high = float(info.tiny), float(info.max) / OVERFLOW_HEADROOM ** 2
    bad = np.flatnonzero((mass < low) | (mass > high))
    if not bad.size:
        return None
    i = int(bad[0])
    return (f"mass of sphere {i} ({mass[i]:.3g} kg) is outside what {precision} can hold "
            f"({low:.2g} .. {high:.2g} kg)" + _more(bad))


def scene_precision_problems(scene, precision: str, step_fraction: float) -> list:
    """What ``precision`` ("f32" | "f64") cannot hold in ``scene``: the fastest speed,
    radii too small to move in the box at ``step_fraction``, masses (speed_problem,
    radius_problem, mass_problem); [] if nothing."""
    problems = [speed_problem(precision, scene.v),
                radius_problem(precision, scene.radius, scene.box_lo, scene.box_hi,
                               step_fraction),
                mass_problem(precision, scene.mass)]
    return [p for p in problems if p]


def spin_problem(omega, frictional: bool, ids=None) -> str | None:
    """Why nonzero spins (N, 3) [rad/s] cannot be given (a scene without friction: they
    would not act and are not simulated), naming the first sphere (``ids``: the scene
    numbers of the rows), or None."""
    spinning = np.flatnonzero(np.any(np.asarray(omega) != 0, axis=1))
    if not spinning.size or frictional:
        return None
    i = spinning[0] if ids is None else ids[spinning[0]]
    return (f"omega of sphere {i} is not zero, but the scene has no friction, so spins "
            f"would not act and are not simulated: give a friction coefficient or leave "
            f"omega out")


def gravity_problem(precision: str, gravity, speed: float) -> str | None:
    """Why gravity [m/s^2], which gives spheres up to ``speed`` [m/s], overflows
    ``precision``, or None."""
    limit = largest_speed(precision)
    g = math.hypot(*(float(c) for c in gravity))
    if speed <= limit and g <= limit ** 2:
        return None
    return (f"gravity {vector_text(gravity)} m/s^2 overflows {precision}: it gives "
            f"spheres speeds up to {speed:.3g} m/s, and {precision} holds at most "
            f"{limit:.2g} m/s")


def _array(name, value, ndim):
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not numeric ({exc})") from None
    if arr.ndim != ndim:
        raise ValueError(f"{name} must be a {ndim}-d array, got shape {arr.shape}")
    return arr


def _per_sphere(name, value, n):
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not numeric ({exc})") from None
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name} of sphere {bad[0]} is not finite ({arr[bad[0]]})"
                         + _more(bad))
    return arr


def _more(bad):
    return f" (and {bad.size - 1} more)" if bad.size > 1 else ""


def _finite_rows(name, arr, ids=None):
    """ValueError naming the first sphere (``ids``: the scene numbers of the rows, default
    the row numbers) whose row of ``arr`` is not finite."""
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        i = bad[0] if ids is None else ids[bad[0]]
        raise ValueError(f"{name} of sphere {i} is not finite ({arr[bad[0]].tolist()})"
                         + _more(bad))


def _positive(name, arr):
    bad = np.flatnonzero(~(arr > 0))
    if bad.size:
        raise ValueError(f"{name} of sphere {bad[0]} must be > 0, got {arr[bad[0]]}" + _more(bad))


def _vector3(name, value):
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be three numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be three finite numbers, got {value!r}")
    return arr


def _periodic(value):
    if isinstance(value, (bool, np.bool_)):
        return (bool(value),) * 3
    try:
        items = tuple(value)
    except TypeError:
        raise ValueError(f"periodic must be a bool or three bools, got {value!r}") from None
    if len(items) != 3 or not all(isinstance(p, (bool, np.bool_)) for p in items):
        raise ValueError(f"periodic must be a bool or three bools, got {value!r}")
    return tuple(bool(p) for p in items)


def _restitution(name, value):
    try:
        e = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= e <= 1.0:
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    return e


def _inside_box(x, radius, lo, hi, periodic):
    for a in range(3):
        if periodic[a]:
            bad = np.flatnonzero((x[:, a] < lo[a]) | (x[:, a] >= hi[a]))
            where = f"[{lo[a]}, {hi[a]}) on periodic axis {'xyz'[a]}"
        else:
            # a sphere given as touching a wall (centre +- radius == wall up to decimal
            # round-off, e.g. 0.2 + 0.1 > 0.3) is accepted, like touching pairs
            slack = radius * TOUCH_TOLERANCE
            bad = np.flatnonzero((x[:, a] - radius < lo[a] - slack)
                                 | (x[:, a] + radius > hi[a] + slack))
            where = f"the walls {lo[a]} .. {hi[a]} on axis {'xyz'[a]} (centre +- radius)"
        if bad.size:
            i = bad[0]
            raise ValueError(f"sphere {i} (x={x[i].tolist()}, radius={radius[i]}) is outside "
                             f"{where}" + _more(bad))


def check_state(x, v, omega, lo, hi, periodic, ids=None) -> None:
    """ValueError naming the first sphere whose position (N, 3) [m], velocity (N, 3)
    [m/s] or spin (N, 3) [rad/s] is not finite, or whose centre lies outside the box
    [lo, hi] (on a periodic axis by more than PERIODIC_SLACK times the largest of |lo|,
    |hi| and the box's extent): the checks of a state given to Simulation.set_state;
    ``ids`` (N,): the scene numbers of the rows, named in the message (default: the row
    numbers). Overlaps with neighbours or walls are not checked: a state the engine
    wrote may hold the small ones its steps leave."""
    ids = np.arange(len(x)) if ids is None else np.asarray(ids)
    for name, arr in (("x", x), ("v", v), ("omega", omega)):
        _finite_rows(name, arr, ids)
    for a in range(3):
        slack = PERIODIC_SLACK * max(abs(lo[a]), abs(hi[a]), hi[a] - lo[a]) \
            if periodic[a] else 0.0
        bad = np.flatnonzero((x[:, a] < lo[a] - slack) | (x[:, a] > hi[a] + slack))
        if bad.size:
            i = bad[0]
            raise ValueError(f"sphere {ids[i]}: centre x={x[i].tolist()} lies outside the "
                             f"box [{lo[a]}, {hi[a]}] on axis {'xyz'[a]}" + _more(bad))


def _no_overlaps(x, radius, lo, hi, periodic):
    """Raise on the first overlapping pair, found with a cell list (O(N) for sane scenes)."""
    i, j, dist = find_first_overlap(x, radius, lo, hi, periodic)
    if i >= 0:
        sigma = radius[i] + radius[j]
        what = "have coincident centres" if dist == 0.0 else \
            f"overlap: distance {dist:.17g} < r_i + r_j = {sigma:.17g}"
        raise ValueError(f"spheres {i} and {j} {what}")


def find_first_overlap(x, radius, lo, hi, periodic, tolerance=TOUCH_TOLERANCE):
    """Lowest-index overlapping pair (i, j, distance) or (-1, -1, nan).

    Vectorised cell list: cells of size >= the largest diameter, each sphere compared
    with the members of its own and the 26 neighbouring cells (minimum image on
    periodic axes). Overlap means distance < (r_i + r_j) (1 - tolerance).
    """
    n = x.shape[0]
    if n < 2:
        return -1, -1, float("nan")
    size = hi - lo
    cell = 2.0 * radius.max()
    ncell = np.maximum(1, np.floor(size / cell)).astype(np.int64)
    ncell = np.minimum(ncell, max(1, int(round(n ** (1 / 3))) * 4))
    c = np.floor((x - lo) / size * ncell).astype(np.int64)
    c = np.clip(c, 0, ncell - 1)
    key = (c[:, 0] * ncell[1] + c[:, 1]) * ncell[2] + c[:, 2]
    order = np.argsort(key, kind="stable")
    skey = key[order]
    best = None
    offsets = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)]
    seen_keys = set()
    for off in offsets:
        nb = c + np.array(off)
        valid = np.ones(n, dtype=bool)
        for a in range(3):
            if periodic[a]:
                nb[:, a] %= ncell[a]
            else:
                valid &= (nb[:, a] >= 0) & (nb[:, a] < ncell[a])
        nkey = (nb[:, 0] * ncell[1] + nb[:, 1]) * ncell[2] + nb[:, 2]
        # on axes with fewer than 3 cells several offsets name the same cell: visit it once
        sig = tuple(off[a] % ncell[a] if periodic[a] else off[a] for a in range(3))
        if sig in seen_keys:
            continue
        seen_keys.add(sig)
        start = np.searchsorted(skey, nkey, side="left")
        stop = np.searchsorted(skey, nkey, side="right")
        stop = np.where(valid, stop, start)
        count = stop - start
        for m in range(int(count.max()) if n else 0):
            sel = np.flatnonzero(count > m)
            jj = order[start[sel] + m]
            ii = sel
            keep = jj > ii
            ii, jj = ii[keep], jj[keep]
            d = x[ii] - x[jj]
            for a in range(3):
                if periodic[a]:
                    d[:, a] -= size[a] * np.round(d[:, a] / size[a])
            dist = np.sqrt((d * d).sum(axis=1))
            sig2 = (radius[ii] + radius[jj]) * (1.0 - tolerance)
            hit = np.flatnonzero(dist < sig2)
            if hit.size:
                cand = sorted(zip(ii[hit].tolist(), jj[hit].tolist(), dist[hit].tolist()))[0]
                if best is None or cand[:2] < best[:2]:
                    best = cand
    if best is None:
        return -1, -1, float("nan")
    return best
