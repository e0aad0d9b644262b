"""Sinks: spheres whose centre enters a sink region leave the simulation (or, with
``recycle``, re-enter at the top of the domain at rest in a free spot).

The step counts the spheres in sinks at the end of its drift (params.in_sinks, read
back with the other counters); when there are some, the Simulation removes them and
continues with the remaining spheres on the same engine (its fields hold up to their
capacity; the contact solver's warm start is renumbered so that the remaining contacts
keep their impulses). Without a recycling sink the engine takes them out in its fields
(takeout.py) and :func:`without` books what left; otherwise :func:`discharge` removes
or recycles them here, on the host, the warm start moved in the engine's fields on the
CPU (contacts/warm_table.py) or renumbered here (renumber_warm).
Numpy only.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Discharged", "in_sinks", "discharge", "without", "renumber_warm", "free_spots",
           "DROPPED_PARTNER"]

#: warm_key of a warm-start row whose partner a sink took out: no sphere's index and no
#: wall's, so no row matches it again
DROPPED_PARTNER = -(2 ** 30)
#: tries per recycled sphere to find a free spot at the top of the domain
SPOT_TRIES = 200


@dataclasses.dataclass
class Discharged:
    """What one discharge removed: count, mass [kg] and energy [J] (kinetic, rotational
    and potential -m g.x) of the spheres taken out (recycled ones included: they
    re-enter at rest elsewhere: the energy is net of the potential energy they come
    back with)."""

    count: int = 0
    mass: float = 0.0
    energy: float = 0.0
    #: (N,) bool: the spheres that stay in the simulation (None: all)
    kept: np.ndarray | None = None


def in_sinks(x: np.ndarray, sinks, dtype) -> np.ndarray:
    """(N,) bool: centre x (N, 3) [m] inside a sink region [low, high), compared in
    the simulation's precision ``dtype`` as the step kernel does."""
    x = np.asarray(x, dtype=dtype)
    out = np.zeros(len(x), dtype=bool)
    for sink in sinks:
        lo = np.asarray(sink.low, dtype=dtype)
        hi = np.asarray(sink.high, dtype=dtype)
        out |= np.all(x >= lo, axis=1) & np.all(x < hi, axis=1)
    return out


def sphere_energy(x, v, omega, radius, mass, gravity) -> np.ndarray:
    """(N,) kinetic + rotational (I = 2/5 m r^2) + potential (-m g.x) energy [J]."""
    ke = 0.5 * mass * np.einsum("ij,ij->i", v, v)
    rot = 0.2 * mass * radius ** 2 * np.einsum("ij,ij->i", omega, omega)
    return ke + rot - mass * (x @ np.asarray(gravity, dtype=np.float64))


def free_spots(scene, x, radius, placed_r, rng) -> np.ndarray | None:
    """Centres (K, 3) [m] at the top of the box for spheres of radii placed_r (K,), not
    overlapping x (N, 3) of radii radius, each other, or any geometry object; None if
    a sphere found no spot in SPOT_TRIES tries."""
    lo, hi = scene.box_lo, scene.box_hi
    others_x, others_r = list(x), list(radius)
    out = []
    for r in placed_r:
        for _ in range(SPOT_TRIES):
            c = np.array([rng.uniform(lo[0] + r, hi[0] - r), rng.uniform(lo[1] + r, hi[1] - r),
                          hi[2] - r * (1 + 1e-6)])
            d = np.linalg.norm(np.asarray(others_x) - c, axis=1) if others_x else np.array([])
            clear = np.all(d >= (np.asarray(others_r) + r) * (1 + 1e-9))
            if clear and all(g.gap(c[None], np.array([r]))[0] >= 0 for g in scene.geometry):
                out.append(c)
                others_x.append(c)
                others_r.append(r)
                break
        else:
            return None
    return np.array(out).reshape(-1, 3)


def renumber_warm(warm: dict | None, keep: np.ndarray) -> dict | None:
    """The contact solver's warm-start table (ContactSolver.warm_rows) for the spheres
    ``keep`` (bool (N,)) only, their partners renumbered; rows with a removed partner
    are dropped (their key can no longer match)."""
    if warm is None:
        return None
    new_index = np.cumsum(keep) - 1
    out = {k: (v[keep] if isinstance(v, np.ndarray) else v) for k, v in warm.items()}
    key = out["key"]
    used = np.arange(key.shape[1])[None, :] < out["kept"][:, None]   # slots in use
    pair = used & (key >= 0) & (key < len(keep))
    partner = np.where(pair, key, 0)
    alive = keep[partner] | ~pair
    out["key"] = np.where(pair, np.where(alive, new_index[partner], DROPPED_PARTNER), key)
    return out


def discharge(scene, rows, warm, dtype, rng):
    """Remove the spheres in the scene's sinks, or move those in a ``recycle`` sink to
    free spots at the top of the box, at rest. rows: (x, v, omega) of the current state
    (n, 3) each. Returns (scene, (x, v, omega), warm, Discharged): the scene with the
    remaining spheres (arrays replaced without validation: they come from a valid
    run), their state and renumbered warm start. Recycled spheres that find no free
    spot stay where they are (tried again at the next discharge)."""
    x, v, omega = (np.array(a, dtype=np.float64) for a in rows)
    back = in_sinks(rows[0], [s for s in scene.sinks if s.recycle], dtype)
    out = in_sinks(rows[0], [s for s in scene.sinks if not s.recycle], dtype) & ~back
    if back.any():
        spots = free_spots(scene, x[~back & ~out], scene.radius[~back & ~out],
                           scene.radius[back], rng)
        if spots is None:
            back[:] = False
        else:
            x[back], v[back], omega[back] = spots, 0.0, 0.0
    taken = out | back
    gone = taken_out(scene, taken, [np.array(a, dtype=np.float64)[taken] for a in rows])
    # a recycled sphere re-enters at rest: its new potential energy comes in
    gone.energy = float(gone.energy - sphere_energy(
        x[back], v[back], omega[back], scene.radius[back], scene.mass[back],
        scene.gravity).sum())
    if not out.any():
        return scene, (x, v, omega), warm, gone
    keep = ~out
    gone.kept = keep
    return (remaining(scene, keep, x[keep], v[keep], omega[keep]),
            (x[keep], v[keep], omega[keep]), renumber_warm(warm, keep), gone)


def taken_out(scene, taken: np.ndarray, rows) -> Discharged:
    """Count, mass [kg] and energy [J] of the spheres ``taken`` ((N,) bool) whose
    x, v, omega are ``rows`` ((k, 3) float64 each, in index order)."""
    energy = sphere_energy(*rows, scene.radius[taken], scene.mass[taken], scene.gravity)
    return Discharged(count=int(taken.sum()), mass=float(scene.mass[taken].sum()),
                      energy=float(energy.sum()))


def remaining(scene, keep: np.ndarray, x, v, omega):
    """The scene of the spheres ``keep`` ((N,) bool) with positions, velocities and
    spins x, v, omega ((n, 3) each) (arrays replaced without validation)."""
    return dataclasses.replace(scene, x=x, v=v, radius=scene.radius[keep],
                               mass=scene.mass[keep], omega=omega,
                               material=scene.material[keep])


def without(scene, keep: np.ndarray, taken_rows):
    """After the engine took the spheres not in ``keep`` ((N,) bool) out of its fields
    (takeout.py): (the scene of those that stay, Discharged). ``taken_rows``: (k, 9)
    x, v, omega of the taken ones in index order. The scene keeps its x, v, omega
    rows for the spheres that stay (the state itself is in the fields)."""
    taken = ~keep
    rows = np.asarray(taken_rows, dtype=np.float64)
    gone = taken_out(scene, taken, [np.ascontiguousarray(rows[:, c:c + 3]) for c in (0, 3, 6)])
    gone.kept = keep
    omega = scene.omega if scene.omega is not None else np.zeros_like(scene.v)
    return remaining(scene, keep, scene.x[keep], scene.v[keep], omega[keep]), gone
