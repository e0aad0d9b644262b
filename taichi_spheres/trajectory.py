"""Trajectories in GSD files (HOOMD schema), which OVITO, freud, MDAnalysis and HOOMD's
own tools read; and initial conditions read back from such a frame.

Frame layout (``gsd.hoomd``, schema ``hoomd``):

- ``configuration/box`` = [Lx, Ly, Lz, 0, 0, 0] (m): the scene's box. HOOMD's box is
  centred at the origin, so positions are stored shifted by the box centre
  (``x - (lo + hi) / 2``). Periodic axes are the box's period; walled axes span the
  walls (HOOMD treats every axis as periodic: on a walled axis nothing crosses the face).
- ``configuration/step``: steps taken since the start (``sim.stats["steps"]``).
- ``particles/N``, ``position`` (m), ``velocity`` (m/s), ``diameter`` (m), ``mass`` (kg),
  ``types`` and ``typeid`` (:func:`particle_types`); ``moment_inertia`` and ``angmom``
  when the state spins (a non-zero angular velocity ``omega``).
- ``log/taichi_spheres/...`` (:data:`LOG_PREFIX`): ``time`` (s), ``kinetic_energy``
  (translational and rotational),
  ``potential_energy``, ``total_energy`` (J), ``momentum`` (kg m/s, 3), the collision
  counters and booked energy losses of :attr:`Simulation.stats`, and the geometry
  needed to restore the scene's own coordinates: ``box_lo`` (m, 3) and ``periodic``
  (3 of 0/1).

Floats are written in the simulation's precision (f64: ``double``, which needs gsd 4
or later to read; f32: ``single``), so a frame read back holds the simulation's bits
(positions up to the rounding of the centre shift, velocities exactly).
"""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from . import observe
from .interrupts import hold_interrupts

__all__ = ["GSDWriter", "StepFrames", "GSDFrame", "read_frame", "scene_from_gsd",
           "particle_types", "LOG_PREFIX", "LOGGED_STATS"]

#: namespace of this package's entries under ``log/`` in a frame
LOG_PREFIX = "taichi_spheres/"
#: Simulation.stats counters logged with every frame
LOGGED_STATS = ("steps", "pair_collisions", "wall_collisions", "wall_rests", "sweeps",
                "max_overlap", "unresolved", "collapse_collisions", "energy_pair_restitution",
                "energy_wall_restitution", "energy_collapse", "energy_contacts", "virial",
                "contacts", "contact_iterations", "discharged", "discharged_mass",
                "energy_discharged")
#: scenes with at most this many distinct radii (and no groups) get one type per radius
MAX_SIZE_TYPES = 16
_GSD_PRECISION = {"f64": "double", "f32": "single"}


def _gsd_hoomd():
    try:
        import gsd.hoomd
    except ImportError:                 # a dependency: only a broken install lacks it
        raise RuntimeError("GSD trajectories need the 'gsd' package: pip install gsd") \
            from None
    return gsd.hoomd


def particle_types(scene) -> tuple[list, np.ndarray]:
    """(type names, (N,) typeid) of a scene's spheres: one type per table of a scene
    file (``lattice[0]``, ``random[1]``, ... from ``scene.meta``), else one per distinct
    radius (``r=0.05``) when there are at most :data:`MAX_SIZE_TYPES`, else one type."""
    groups, names = scene.meta.get("groups"), scene.meta.get("group_names")
    if groups is not None and names is not None and len(names) > int(np.max(groups)):
        return list(names), np.asarray(groups, dtype=np.uint32)
    radii, typeid = np.unique(scene.radius, return_inverse=True)
    if len(radii) <= MAX_SIZE_TYPES:
        return [f"r={r:g}" for r in radii], typeid.astype(np.uint32)
    return ["sphere"], np.zeros(scene.n, dtype=np.uint32)


def _box_centre(lo, hi):
    return 0.5 * (np.asarray(lo, dtype=np.float64) + np.asarray(hi, dtype=np.float64))


def _wrapped(x, lo, hi, periodic):
    """Positions with periodic axes wrapped into [lo, hi) (others unchanged) [m]."""
    x = np.array(x, dtype=np.float64)
    for a in range(3):
        if periodic[a]:
            size = hi[a] - lo[a]
            outside = (x[:, a] < lo[a]) | (x[:, a] >= hi[a])
            x[outside, a] = lo[a] + np.mod(x[outside, a] - lo[a], size)
    return x


def _rotation(frame, state):
    """``moment_inertia`` (I = 2/5 m r^2 about every axis) and HOOMD's ``angmom``
    quaternion for identity orientations, 2 (0, I omega), when the state spins."""
    omega = getattr(state, "omega", None)
    if omega is None or not np.any(omega):
        return
    inertia = 0.4 * state.mass * state.radius ** 2
    frame.particles.moment_inertia = np.repeat(inertia[:, None], 3, axis=1)
    angmom = np.zeros((len(inertia), 4))
    angmom[:, 1:] = 2.0 * inertia[:, None] * np.asarray(omega, dtype=np.float64)
    frame.particles.angmom = angmom


def _log(state, stats, scene) -> dict:
    """The ``log/`` entries of one frame (see the module docstring)."""
    ke = observe.kinetic_energy(state) + observe.rotational_energy(state)
    pe = observe.potential_energy(state, scene.gravity)
    log = {"time": np.array([state.time]), "kinetic_energy": np.array([ke]),
           "potential_energy": np.array([pe]), "total_energy": np.array([ke + pe]),
           "momentum": observe.momentum(state),
           "box_lo": np.asarray(scene.box_lo, dtype=np.float64),
           "periodic": np.array(scene.periodic, dtype=np.uint8)}
    for key in LOGGED_STATS:
        if key in stats:
            dtype = np.float64 if isinstance(stats[key], float) else np.int64
            log[key] = np.array([stats[key]], dtype=dtype)
    return {LOG_PREFIX + k: v for k, v in log.items()}


def make_frame(state, stats: dict, scene, types=None):
    """A ``gsd.hoomd.Frame`` of a State (x, v (N, 3); radius, mass (N,); time) with the
    counters ``stats`` of the Simulation of ``scene``; ``types``: particle_types(scene)."""
    frame = _gsd_hoomd().Frame()
    lo, hi = scene.box_lo, scene.box_hi
    size = np.asarray(hi, dtype=np.float64) - lo
    frame.configuration.box = [size[0], size[1], size[2], 0.0, 0.0, 0.0]
    frame.configuration.step = int(stats.get("steps", 0))
    frame.configuration.dimensions = 3
    names, typeid = types or particle_types(scene)
    p = frame.particles
    p.N = len(state.x)
    p.position = _wrapped(state.x, lo, hi, scene.periodic) - _box_centre(lo, hi)
    p.velocity = np.asarray(state.v, dtype=np.float64)
    p.diameter = 2.0 * np.asarray(state.radius, dtype=np.float64)
    p.mass = np.asarray(state.mass, dtype=np.float64)
    p.types, p.typeid = names, typeid
    _rotation(frame, state)
    frame.log = _log(state, stats, scene)
    return frame


class GSDWriter:
    """Append frames of a Simulation to a GSD file (HOOMD schema, module docstring).

    ``GSDWriter(path)`` creates (or overwrites) ``path``; ``append(sim)`` writes one frame
    of ``sim``'s current state and flushes it to disk, so a run stopped at any point
    (Ctrl-C, a crash) leaves a valid file with every frame appended so far; Ctrl-C is
    held while a frame is written. precision: "double", "single" or None (the first
    Simulation's: f64 -> double, f32 -> single). keep_until_step: keep the frames of an
    existing file with ``configuration/step`` <= this (continuing a run from a
    checkpoint); None starts a new file. Use as a context manager or call close().
    """

    def __init__(self, path, precision: str | None = None, keep_until_step: int | None = None):
        from .output import check_writable
        if precision not in (None, "double", "single"):
            raise ValueError(f"precision must be 'double', 'single' or None, got {precision!r}")
        self.path = os.fspath(path)
        check_writable(self.path)
        self.precision = precision
        self.keep_until_step = keep_until_step
        self.frames = 0
        self._file = None
        self._types = None

    def append(self, sim) -> None:
        """Write ``sim``'s current state as the next frame (flushed at once)."""
        state = sim.state()
        if self._file is None:
            self._open(_GSD_PRECISION.get(getattr(sim, "precision", "f64"), "double"))
            # the types of the scene the run started from: sphere_ids index it
            self._types = particle_types(getattr(sim, "original_scene", sim.scene))
        names, typeid = self._types
        ids = getattr(sim, "sphere_ids", None)     # spheres still in (sinks take some out)
        if ids is not None and len(ids) != len(typeid):
            typeid = typeid[ids]
        frame = make_frame(state, sim.stats, sim.scene, (names, typeid))
        with hold_interrupts():
            self._file.append(frame)
            self._file.flush()
            self.frames += 1

    def _open(self, precision):
        hoomd = _gsd_hoomd()
        precision = self.precision or precision
        earlier = None
        if self.keep_until_step is not None:
            earlier = _set_aside(self.path)
        self._file = hoomd.open(self.path, "w", precision=precision)
        if earlier:
            self.frames = _copy_frames(hoomd, earlier, self._file, self.keep_until_step)
            os.remove(earlier)

    def close(self) -> None:
        if self._file is not None:
            with hold_interrupts():
                self._file.close()
                self._file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _set_aside(path) -> str | None:
    """Move an earlier trajectory out of the way before it is copied into a new file;
    returns its new path. If an earlier copy was interrupted (the set-aside file is
    still there), that file is the earlier trajectory and ``path`` a partial copy."""
    old = path + ".before-resume.gsd"
    if not os.path.exists(old):
        if not os.path.exists(path):
            return None
        os.replace(path, old)
    return old


def _copy_frames(hoomd, source, target, last_step) -> int:
    """Copy the frames of file ``source`` with step <= last_step into ``target``."""
    copied = 0
    with hoomd.open(source, "r") as earlier:
        for frame in earlier:
            if frame.configuration.step > last_step:
                break
            target.append(frame)
            copied += 1
    target.flush()
    return copied


class StepFrames:
    """Append a frame to ``writer`` after every ``every``-th step of ``sim`` (counting
    from the start of the run: steps 0 (the initial state, when ``sim`` has not stepped
    yet), every, 2 every, ...), without changing the
    simulation: it wraps ``sim.step`` and writes a due frame just before the next step
    begins, or at :meth:`flush` (call it after each ``advance``/``advance_to``), when
    ``sim.time`` and ``sim.stats`` describe the state. :meth:`detach` restores ``sim``.
    """

    def __init__(self, sim, writer: GSDWriter, every: int):
        if not isinstance(every, int) or every < 1:
            raise ValueError(f"every must be a positive number of steps, got {every!r}")
        self.sim, self.writer, self.every = sim, writer, every
        self.steps = int(sim.stats["steps"])
        self.due = self.steps == 0          # the initial state is frame 0 of a run
        self._step = sim.step
        sim.step = self._step_and_mark

    def _step_and_mark(self, h):
        self.flush()
        taken = self._step(h)
        self.steps += 1
        self.due = self.steps % self.every == 0
        return taken

    def flush(self) -> None:
        """Write the frame that is due, if any."""
        if self.due:
            self.due = False
            self.writer.append(self.sim)

    def detach(self) -> None:
        """Stop recording (a frame still due is dropped: call flush first)."""
        if self.sim.__dict__.get("step") == self._step_and_mark:
            del self.sim.step


@dataclasses.dataclass
class GSDFrame:
    """One frame read from a GSD file, in the scene's coordinates.

    x, v: (N, 3) [m], [m/s]; radius, mass: (N,) [m], [kg]; box_lo, box_hi: (3,) [m]
    (this package's own frames: the box they were written from; other files: HOOMD's
    box, centred at the origin); periodic: 3 bools, or None when the file does not say
    (HOOMD's boxes are periodic); types: names; typeid: (N,); time [s] (0 when not
    logged); step; frame: its index in the file; frames: frames in the file; omega:
    (N, 3) angular velocities [rad/s] from ``angmom`` / (2 ``moment_inertia``), the
    writer's convention (_rotation; zeros where the file holds no spin)."""

    x: np.ndarray
    v: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    periodic: tuple | None
    types: list
    typeid: np.ndarray
    time: float
    step: int
    frame: int
    frames: int
    omega: np.ndarray | None = None


def read_frame(path, frame: int = -1) -> GSDFrame:
    """Read frame ``frame`` (negative: from the end; -1 the last) of a GSD file.

    Raises ValueError naming the file and what is wrong: missing or unreadable, not a
    HOOMD-schema GSD file, no frame of that index, no particles, a tilted or flat box.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"GSD file not found: {path}")
    hoomd = _gsd_hoomd()
    try:
        with hoomd.open(path, "r") as traj:
            count = len(traj)
            if not -count <= frame < count:
                raise ValueError(f"{path} has {count} frame(s); frame {frame} does not "
                                 f"exist (0..{count - 1}, or -1 for the last)")
            index = frame % count
            data = traj[index]
    except (RuntimeError, OSError) as exc:
        raise ValueError(f"cannot read GSD file {path}: {exc}") from None
    return _frame_from_gsd(data, path, index, count)


def _frame_from_gsd(data, path, index, count) -> GSDFrame:
    """GSDFrame of a ``gsd.hoomd.Frame`` (ValueError naming the file at fault)."""
    box = np.asarray(data.configuration.box, dtype=np.float64)
    where = f"{path} frame {index}"
    if np.any(box[3:] != 0.0):
        raise ValueError(f"{where}: tilted box (xy, xz, yz = {box[3:].tolist()}); only "
                         f"rectangular boxes can be simulated")
    if not np.all(box[:3] > 0.0):
        raise ValueError(f"{where}: box lengths must be > 0, got {box[:3].tolist()} "
                         f"(a 2D frame cannot be simulated)")
    p = data.particles
    if not p.N:
        raise ValueError(f"{where}: no particles")
    log = data.log
    lo = np.asarray(log.get(LOG_PREFIX + "box_lo", -0.5 * box[:3]), dtype=np.float64)
    hi = lo + box[:3]
    periodic = log.get(LOG_PREFIX + "periodic")
    time = log.get(LOG_PREFIX + "time")
    return GSDFrame(
        x=np.asarray(p.position, dtype=np.float64) + _box_centre(lo, hi),
        v=np.asarray(p.velocity, dtype=np.float64), mass=np.asarray(p.mass, np.float64),
        radius=0.5 * np.asarray(p.diameter, dtype=np.float64), box_lo=lo, box_hi=hi,
        periodic=None if periodic is None else tuple(bool(a) for a in periodic),
        types=list(p.types), typeid=np.asarray(p.typeid, dtype=np.int64),
        time=0.0 if time is None else float(np.ravel(time)[0]),
        step=int(data.configuration.step), frame=index, frames=count, omega=_spins(p))


def _spins(p) -> np.ndarray:
    """(N, 3) angular velocities [rad/s] of a frame's particles: the vector part of
    HOOMD's ``angmom`` over twice ``moment_inertia`` (the inverse of _rotation for a
    sphere, whose orientation is the identity); zero where the moment of inertia is."""
    angmom = np.asarray(p.angmom, dtype=np.float64).reshape(-1, 4)[:, 1:]
    inertia = np.asarray(p.moment_inertia, dtype=np.float64).reshape(-1, 3)
    out = np.zeros_like(angmom)
    np.divide(angmom, 2.0 * inertia, out=out, where=inertia > 0)
    return out


def scene_from_gsd(path, frame: int = -1, box=None, periodic=None, **physics):
    """A :class:`Scene` whose spheres (positions, velocities, radii, masses, types, and
    spins where the file holds them and the scene has friction) are frame ``frame`` of
    a GSD file (-1: the last), e.g. to continue a run or start from another tool's
    output.

    box: ((lo), (hi)) [m], default the frame's (this package's frames keep the box they
    were written from; other files give HOOMD's box centred at the origin); positions are
    placed relative to the box centre. periodic: default the frame's (other files: all
    axes, as in HOOMD). physics: the other arguments of :meth:`Scene.from_arrays`
    (gravity, restitution, ...). ValueError names the file or the sphere at fault.
    """
    from .scene import Scene
    data = read_frame(path, frame)
    if np.any(data.typeid < 0) or np.any(data.typeid >= max(len(data.types), 1)):
        raise ValueError(f"{path} frame {data.frame}: typeid outside the {len(data.types)} "
                         f"types")
    lo, hi = (data.box_lo, data.box_hi) if box is None else \
        (np.asarray(box[0], np.float64), np.asarray(box[1], np.float64))
    x = data.x - _box_centre(data.box_lo, data.box_hi) + _box_centre(lo, hi)
    if periodic is None:
        periodic = data.periodic if data.periodic is not None else (True, True, True)
    physics.setdefault("name", os.path.splitext(os.path.basename(os.fspath(path)))[0])
    physics.setdefault("gravity", (0.0, 0.0, 0.0))
    scene = Scene.from_arrays(x, data.v, data.radius, mass=data.mass, box=(lo, hi),
                              periodic=periodic, **physics)
    if "omega" not in physics and scene.frictional and np.any(data.omega != 0):
        scene = scene.replace(omega=data.omega)     # spins act only with friction
    meta = {"groups": data.typeid, "group_names": data.types,
            "group_colours": np.full((len(data.types), 3), -1.0),
            "initial": {"gsd": os.fspath(path), "frame": data.frame, "time": data.time,
                        "step": data.step}}
    return dataclasses.replace(scene, meta=meta)
