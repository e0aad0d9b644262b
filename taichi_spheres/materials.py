"""Materials: per-sphere contact coefficients (scene layer, plain numpy).

A scene has one material unless it is given ``materials`` (a sequence of
:class:`Material`) and ``material`` (the (N,) index of each sphere's material). A
material's coefficients left None take the scene's own values (``restitution``,
``friction``, ``rolling_friction``). A pair of spheres of materials a and b collides and
rubs with the *pair values*: by default the smaller of the two materials' restitution,
friction and rolling friction (a pair is as lossy and as smooth as its weaker side);
``material_pairs`` overrides any pair, e.g. a measured glass-on-steel restitution.

Walls and geometry keep their own values (``wall_restitution``, ``wall_friction``, a
ts.Plane's ``restitution``...): a material sets what its spheres do to each other. The
rolling resistance of a sphere on a wall is its own material's ``rolling_friction``.
The tangential restitution (Walton's beta0) stays one value per scene.

The engine compiles the table lookups in only when the pair values differ between
materials (state.Features.materials); otherwise it reads the single value as before.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .geometry import optional_number

__all__ = ["Material", "MAX_MATERIALS", "COEFFICIENTS", "resolved", "pair_table",
           "material_indices", "resolved_pairs"]

#: materials a scene may have (the pair table is MAX_MATERIALS^2 entries on the device)
MAX_MATERIALS = 16
#: the pair values of the table, in its last axis
COEFFICIENTS = ("restitution", "friction", "rolling_friction")
_HIGH = {"restitution": 1.0, "friction": math.inf, "rolling_friction": math.inf}


@dataclasses.dataclass(frozen=True)
class Material:
    """Contact coefficients of a kind of sphere: restitution e in [0, 1], Coulomb
    friction mu >= 0, rolling friction mu_r >= 0 (None: the scene's value); name: free
    text (scene files refer to materials by it)."""

    name: str = ""
    restitution: float | None = None
    friction: float | None = None
    rolling_friction: float | None = None

    def __post_init__(self):
        owner = f"Material {self.name!r}" if self.name else "Material"
        for key in COEFFICIENTS:
            object.__setattr__(self, key, optional_number(owner, key, getattr(self, key),
                                                    high=_HIGH[key]))
        object.__setattr__(self, "name", str(self.name))

    def values(self) -> tuple:
        """(restitution, friction, rolling_friction) of a resolved material."""
        return tuple(getattr(self, key) for key in COEFFICIENTS)


def resolved(materials, defaults: dict) -> tuple:
    """The scene's materials with None coefficients replaced by ``defaults`` (a dict of
    COEFFICIENTS: the scene's values); no materials: one material of the defaults."""
    materials = tuple(materials or ())
    if len(materials) > MAX_MATERIALS:
        raise ValueError(f"materials: at most {MAX_MATERIALS}, got {len(materials)}")
    if not materials:
        materials = (Material(),)
    out = []
    for k, m in enumerate(materials):
        if not isinstance(m, Material):
            raise ValueError(f"materials[{k}] must be a ts.Material, got {type(m).__name__}")
        fill = {key: defaults[key] for key in COEFFICIENTS if getattr(m, key) is None}
        out.append(dataclasses.replace(m, **fill))
    names = [m.name for m in out if m.name]
    if len(set(names)) != len(names):
        raise ValueError(f"materials: names must differ, got {names}")
    return tuple(out)


def material_indices(material, n: int, count: int) -> np.ndarray:
    """(n,) int32 material index of each sphere (None: all 0), each in [0, count)."""
    if material is None:
        return np.zeros(n, dtype=np.int32)
    arr = np.asarray(material)
    if arr.ndim == 0:
        arr = np.full(n, arr)
    if arr.shape != (n,):
        raise ValueError(f"material must be one index or shape ({n},), got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"material must hold integer indices, got dtype {arr.dtype}")
    bad = np.flatnonzero((arr < 0) | (arr >= count))
    if bad.size:
        raise ValueError(f"material of sphere {bad[0]} is {arr[bad[0]]}, not an index of "
                         f"the {count} material(s) given")
    return arr.astype(np.int32)


def resolved_pairs(pairs, count: int) -> dict:
    """{(a, b): Material} overrides, a <= b, checked against ``count`` materials; a pair
    given twice ((a, b) and (b, a)) is an error naming it, not a silent last choice."""
    out = {}
    for key, m in dict(pairs or {}).items():
        try:
            a, b = (int(k) for k in key)
        except (TypeError, ValueError):
            raise ValueError(f"material_pairs keys must be (a, b) index pairs, got {key!r}") \
                from None
        if not (0 <= a < count and 0 <= b < count):
            raise ValueError(f"material_pairs[{key!r}]: indices must be in [0, {count})")
        if not isinstance(m, Material):
            raise ValueError(f"material_pairs[{key!r}] must be a ts.Material")
        pair = (min(a, b), max(a, b))
        if pair in out:
            raise ValueError(f"material_pairs: the pair {pair} is given twice "
                             f"({key!r} and its reverse)")
        out[pair] = m
    return out


def pair_table(materials, pairs=None) -> np.ndarray:
    """(M, M, 3) float64 pair values (COEFFICIENTS) of M resolved materials: the smaller
    of the two materials' values, or the override in ``pairs`` ({(a, b): Material}, a
    <= b; its None coefficients keep the smaller value)."""
    values = np.array([m.values() for m in materials], dtype=np.float64)
    table = np.minimum(values[:, None, :], values[None, :, :])
    for (a, b), m in (pairs or {}).items():
        for c, key in enumerate(COEFFICIENTS):
            if getattr(m, key) is not None:
                table[a, b, c] = table[b, a, c] = getattr(m, key)
    return table
