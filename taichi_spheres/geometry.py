"""Static geometry besides the box, and sinks (scene layer: plain numpy, no Taichi).

Each object takes ``restitution=None, friction=None`` (None: the scene's wall values,
filled in by :meth:`Scene.from_arrays`). Gaps are distances between a sphere's surface
and the object's [m], negative when the sphere is inside it; the engine's kernels
(surfaces.py) compute the same, except behind a finite cone or cylinder (below).

- :class:`Plane` ``(point, normal, hole=None)``: the solid is the half-space
  ``(x - point).n < 0`` (n = normal / |normal|); with ``hole = R_h`` a cylindrical
  orifice of radius R_h along n, centred at ``point``, is drilled through it (a silo's
  outlet). With z = (c - point).n and rho the distance of a centre c from the line
  through point along n: gap = z - r where rho >= R_h; over the orifice
  sqrt((R_h - rho)^2 + z^2) - r above the plane (its rim) and R_h - rho - r below it
  (the orifice's wall).
- :class:`Cone` ``(point, axis, radius_at_point, radius_at_end, length, inside=True)``:
  a zero-thickness surface of revolution about the axis through point; in the meridian
  plane (t along the axis, rho from it) the segment (0, radius_at_point) - (length,
  radius_at_end). The gap is the signed distance to it minus r (positive on the axis
  side for ``inside``, on the far side otherwise) where the centre projects onto the
  segment, else the distance to the nearer end rim minus r (a hopper's outlet edge).
  A finite cone is a shell with two faces, as in the run (surfaces.py): a sphere that
  goes round an open end to its back meets the back face, and ``gap(..., both_faces=
  True)`` measures that face there (|signed distance| - r). Starts are checked with
  both faces (a sphere may start behind a finite shell, not across it); spheres the
  package places itself (``[[pour]]`` and ``[[random]]`` tables, recycled spheres) go
  on the front side.
- :class:`Cylinder` ``(point, axis, radius, length=None, inside=True)``: a cone with
  both radii equal; ``length=None`` is infinite (no rims, and its back stays solid in
  the run); a finite one with ``inside=False`` is an open tube in the run.
- :class:`Sink` ``(low, high, recycle=False)``: a box region; a sphere whose centre is
  in [low, high) leaves the simulation (or, with ``recycle``, re-enters at the top of
  the box at rest in a free spot).

``packed()`` gives the engine one row of PACKED_WIDTH numbers:
``[kind, px, py, pz, ax, ay, az, r0, r1, length, inside, hole, restitution, friction]``
(kind PLANE or CONE; (ax, ay, az) the unit normal or axis; length -1 for an infinite
cylinder and 0 for a plane; inside 1 or 0; hole R_h or 0).
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

__all__ = ["Plane", "Cylinder", "Cone", "Sink", "PACKED_WIDTH", "PLANE", "CONE", "resolved",
           "check_sinks", "hole_problem", "inside_problem", "with_material", "optional_number"]

PACKED_WIDTH = 14
PLANE, CONE = 0, 1


def _vector(owner, key, value) -> np.ndarray:
    """A finite 3-vector (float64) or ValueError naming owner.key."""
    try:
        out = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{key} must be 3 numbers, got {value!r}") from None
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{owner}.{key} must be finite, got {out.tolist()}")
    return out


def _unit(owner, key, value) -> np.ndarray:
    """The unit vector along value, or ValueError for a zero vector."""
    v = _vector(owner, key, value)
    size = float(np.linalg.norm(v))
    if size == 0.0:
        raise ValueError(f"{owner}.{key} must not be zero")
    return v / size


def optional_number(owner, key, value, low=0.0, high=math.inf, strict=False):
    """None, or a finite float in [low, high] ((low, high] when strict), else ValueError
    naming owner.key."""
    if value is None:
        return None
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{key} must be a number, got {value!r}") from None
    bad = not (out > low if strict else out >= low) or not out <= high or \
        not math.isfinite(out)
    if bad:
        side = ">" if strict else ">="
        rng = f"{side} {low:g}" + ("" if math.isinf(high) else f" and <= {high:g}")
        raise ValueError(f"{owner}.{key} must be {rng}, got {value!r}")
    return out


def _material(owner, restitution, friction):
    """(restitution in [0, 1] or None, friction >= 0 or None), checked."""
    return (optional_number(owner, "restitution", restitution, 0.0, 1.0),
            optional_number(owner, "friction", friction))


def _radial(d, axis):
    """(t, rho) of offsets d (N, 3) along a unit axis and from it."""
    t = d @ axis
    rho = np.linalg.norm(d - t[:, None] * axis, axis=1)
    return t, rho


@dataclasses.dataclass(frozen=True)
class Plane:
    """A half-space with an optional circular orifice (module docstring)."""

    point: np.ndarray
    normal: np.ndarray
    hole: float | None = None
    restitution: float | None = None
    friction: float | None = None

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "point", _vector("Plane", "point", self.point))
        set_(self, "normal", _unit("Plane", "normal", self.normal))
        set_(self, "hole", optional_number("Plane", "hole", self.hole, strict=True))
        e, mu = _material("Plane", self.restitution, self.friction)
        set_(self, "restitution", e)
        set_(self, "friction", mu)

    def gap(self, x, r, both_faces=False) -> np.ndarray:
        """(N,) gaps [m] of spheres at x (N, 3) of radii r (N,) (``both_faces``: no
        effect, a plane has one face)."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        r = np.broadcast_to(np.asarray(r, dtype=np.float64), (len(x),))
        z, rho = _radial(x - self.point, self.normal)
        out = z - r
        if self.hole:
            over = rho < self.hole
            rim = np.hypot(self.hole - rho, z) - r
            wall = self.hole - rho - r
            out = np.where(over, np.where(z >= 0, rim, wall), out)
        return out

    def packed(self) -> np.ndarray:
        return _pack(PLANE, self.point, self.normal, 0.0, 0.0, 0.0, True, self.hole or 0.0,
                     self.restitution, self.friction, "Plane")


@dataclasses.dataclass(frozen=True)
class Cone:
    """A conical surface (a hopper) about an axis (module docstring)."""

    point: np.ndarray
    axis: np.ndarray
    radius_at_point: float
    radius_at_end: float
    length: float | None
    inside: bool = True
    restitution: float | None = None
    friction: float | None = None

    def __post_init__(self):
        name = type(self).__name__
        set_ = object.__setattr__
        set_(self, "point", _vector(name, "point", self.point))
        set_(self, "axis", _unit(name, "axis", self.axis))
        for key in ("radius_at_point", "radius_at_end"):
            if getattr(self, key) is None:
                raise ValueError(f"{name}.{key} must be a number >= 0")
            set_(self, key, optional_number(name, key, getattr(self, key)))
        if self.radius_at_point == 0 and self.radius_at_end == 0:
            raise ValueError(f"{name}: radius_at_point and radius_at_end must not both be 0")
        if self.length is not None or name == "Cone":
            if self.length is None:
                raise ValueError("Cone.length must be a number > 0")
            set_(self, "length", optional_number(name, "length", self.length, strict=True))
            if math.isinf(self.length):
                raise ValueError(f"{name}.length must be finite")
        if not isinstance(self.inside, (bool, np.bool_)):
            raise ValueError(f"{name}.inside must be true or false, got {self.inside!r}")
        e, mu = _material(name, self.restitution, self.friction)
        set_(self, "restitution", e)
        set_(self, "friction", mu)

    def gap(self, x, r, both_faces=False) -> np.ndarray:
        """(N,) gaps [m] of spheres at x (N, 3) of radii r (N,): to the front face (the
        side ``inside`` names), or with ``both_faces`` to the face on the centre's side
        of a finite shell, as the run sees it (surfaces.py ``cone_gap``)."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        r = np.broadcast_to(np.asarray(r, dtype=np.float64), (len(x),))
        t, rho = _radial(x - self.point, self.axis)
        r0, r1 = self.radius_at_point, self.radius_at_end
        seg = np.array([1.0, 0.0]) if self.length is None else np.array([self.length, r1 - r0])
        span = float(np.hypot(*seg))
        along = (t * seg[0] + (rho - r0) * seg[1]) / span ** 2
        sign = 1.0 if self.inside else -1.0
        side = sign * (t * seg[1] - (rho - r0) * seg[0]) / span
        if self.length is None:
            return side - r
        signed = (np.abs(side) if both_faces else side) - r
        end_t = np.where(along >= 1, self.length, 0.0)
        end_r = np.where(along >= 1, r1, r0)
        rim = np.hypot(t - end_t, rho - end_r) - r
        return np.where((along > 0) & (along < 1), signed, rim)

    def packed(self) -> np.ndarray:
        return _pack(CONE, self.point, self.axis, self.radius_at_point, self.radius_at_end,
                     -1.0 if self.length is None else self.length, self.inside, 0.0,
                     self.restitution, self.friction, type(self).__name__)


@dataclasses.dataclass(frozen=True, init=False)
class Cylinder(Cone):
    """A cylindrical surface about an axis, finite (length) or not (module docstring)."""

    def __init__(self, point, axis, radius, length=None, inside=True, restitution=None,
                 friction=None):
        if radius is None or not float(radius) > 0:
            raise ValueError(f"Cylinder.radius must be > 0, got {radius!r}")
        super().__init__(point, axis, float(radius), float(radius), length, inside,
                         restitution, friction)

    @property
    def radius(self) -> float:
        return self.radius_at_point

    def __repr__(self):
        return (f"Cylinder(point={self.point.tolist()}, axis={self.axis.tolist()}, "
                f"radius={self.radius}, length={self.length}, inside={self.inside})")


def _pack(kind, point, axis, r0, r1, length, inside, hole, restitution, friction, name):
    """One packed row (module docstring); restitution and friction must be resolved."""
    if restitution is None or friction is None:
        raise ValueError(f"{name}: restitution and friction must be resolved (Scene does it)")
    return np.array([kind, *point, *axis, r0, r1, length, 1.0 if inside else 0.0, hole,
                     restitution, friction], dtype=np.float64)


@dataclasses.dataclass(frozen=True)
class Sink:
    """A box region that discharges spheres (module docstring)."""

    low: np.ndarray
    high: np.ndarray
    recycle: bool = False

    def __post_init__(self):
        object.__setattr__(self, "low", _vector("Sink", "low", self.low))
        object.__setattr__(self, "high", _vector("Sink", "high", self.high))
        if not np.all(self.low < self.high):
            raise ValueError("Sink.low must be below Sink.high on every axis, got "
                             f"{self.low.tolist()} and {self.high.tolist()}")
        if not isinstance(self.recycle, (bool, np.bool_)):
            raise ValueError(f"Sink.recycle must be true or false, got {self.recycle!r}")

    def contains(self, x) -> np.ndarray:
        """(N,) bool: centres x (N, 3) in [low, high)."""
        x = np.atleast_2d(x)
        return np.all(x >= self.low, axis=1) & np.all(x < self.high, axis=1)


def resolved(geometry, wall_restitution: float, wall_friction: float) -> tuple:
    """The geometry objects (a sequence) checked and with restitution and friction None
    replaced by the scene's wall values."""
    out = []
    for k, g in enumerate(geometry):
        if not isinstance(g, (Plane, Cone)):
            raise ValueError(f"geometry[{k}] must be a ts.Plane, ts.Cylinder or ts.Cone, "
                             f"got {type(g).__name__}")
        out.append(with_material(g, wall_restitution if g.restitution is None else g.restitution,
                                 wall_friction if g.friction is None else g.friction))
    return tuple(out)


def with_material(g, restitution: float, friction: float):
    """A copy of geometry object g with the given restitution and friction."""
    e, mu = _material(type(g).__name__, restitution, friction)
    g = copy.copy(g)
    object.__setattr__(g, "restitution", e)
    object.__setattr__(g, "friction", mu)
    return g


def check_sinks(sinks, lo, hi) -> tuple:
    """The sinks (a sequence of Sink) checked to overlap the box [lo, hi]."""
    out = tuple(sinks)
    for k, s in enumerate(out):
        if not isinstance(s, Sink):
            raise ValueError(f"sinks[{k}] must be a ts.Sink, got {type(s).__name__}")
        if np.any(s.high <= lo) or np.any(s.low >= hi):
            raise ValueError(f"sinks[{k}] ({s.low.tolist()} .. {s.high.tolist()}) lies "
                             "outside the box")
    return out


def hole_problem(k, plane, lo, hi) -> str | None:
    """Why a plane's orifice reaches outside the box [lo, hi], or None."""
    if not plane.hole:
        return None
    n = plane.normal
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    ang = np.linspace(0.0, 2 * math.pi, 64, endpoint=False)
    rim = plane.point + plane.hole * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w)
    slack = 1e-9 * float(np.max(hi - lo))
    if np.all(rim >= lo - slack) and np.all(rim <= hi + slack):
        return None
    return (f"geometry[{k}] (Plane): hole {plane.hole:g} m reaches outside the box")


def inside_problem(x, radius, geometry, tolerance) -> str | None:
    """Why a sphere starts inside a geometry object (gap < -tolerance x radius, with
    both faces of a finite shell, as in the run), or None: names the first such sphere
    and object."""
    for k, g in enumerate(geometry):
        gap = g.gap(x, radius, both_faces=True)
        bad = np.flatnonzero(gap < -tolerance * radius)
        if bad.size:
            i = int(bad[0])
            return (f"sphere {i} starts inside geometry[{k}] ({type(g).__name__}): gap "
                    f"{gap[i]:.3g} m" + (f" (and {bad.size - 1} more)" if bad.size > 1 else ""))
    return None
