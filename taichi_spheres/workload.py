"""The work a run needs, estimated from its scene before it steps (``taichi-spheres run``
and ``info``), and what a precision can hold.

A step moves no sphere more than D = step_fraction x the smallest radius (see
``Simulation.max_step``): with the fastest speed v and gravity g the step is
h = 2 D / (v + sqrt(v^2 + 2 g D)). Over a run the fastest speed grows with gravity,
v(t) = v0 + g t, up to what a fall across the box adds, sqrt(v0^2 + 2 sum_a |g_a| L_a)
(without bound along a periodic axis with gravity); every frame also ends a step. The
integral of 1/h over the run plus the frame count is the estimate: an order of
magnitude (collisions can speed single spheres up, dense piles spend more contact-solver sweeps per step,
inelastic collisions slow spheres down).

Pure numpy and the Simulation's public API: importing this module does not import Taichi.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from .scene import fall_speed, gravity_problem, scene_precision_problems, vector_text

__all__ = ["MAX_STEPS", "Workload", "estimate", "frame_count", "frame_time",
           "precision_problems", "refusal", "model_step_seconds", "measure_step_seconds",
           "rough_duration"]

#: Estimated steps above which ``taichi-spheres run`` refuses to start unless given
#: --force. No real scene comes near it: the bundled scenes need 10^3 to 10^5 steps for
#: their runs (``taichi-spheres info``), and 10^7 steps are about 20 minutes of stepping
#: for five spheres and days for 10^5 spheres on a 2-core CPU. Scenes above it are
#: mostly slips of units or typos: a speed of 1e300 m/s, gravity of -1e12 m/s^2, a
#: radius in metres that was meant in millimetres, fps = 1e9.
MAX_STEPS = 10**7
#: A run refused at MAX_STEPS whose rate would fit this many simulated seconds [s] under
#: the limit is refused for its duration (refusal), not for its speeds or frames.
LONG_RUN_SECONDS = 10.0
#: time samples of the speed bound when summing 1/h over a run
ESTIMATE_SAMPLES = 1024
#: Seconds a step takes on the reference machine (2-core x86-64 CPU, f64, fast compile,
#: kernels compiled): 1.2e-4 s for the five spheres of scenes/seed_five.toml ...
REFERENCE_STEP_SECONDS = 1.2e-4
#: ... plus this much per sphere (about 10^7 sphere-steps/s at N = 10^5, docs/bench.md;
#: 4,096 spheres of scenes/gas.toml: 0.8 ms a step).
REFERENCE_SPHERE_STEP_SECONDS = 1.5e-7
#: Calibration (:func:`measure_step_seconds`): steps are timed in batches of at least
#: this many seconds [s] and CALIBRATION_BATCH_STEPS steps ...
CALIBRATION_BATCH_SECONDS = 0.1
CALIBRATION_BATCH_STEPS = 3
#: ... until a batch is no faster than the one before by this factor (the kernels that
#: compile on first use are compiled) ...
CALIBRATION_STEADY_RATIO = 1.5
#: ... or this many seconds have passed [s] (compiling included).
CALIBRATION_MAX_SECONDS = 30.0


@dataclasses.dataclass(frozen=True)
class Workload:
    """What a run needs: ``steps`` (estimated, float, may be inf) for ``frames`` frames
    over ``duration`` [s]; the step bound's inputs: step_fraction, the smallest radius
    ``r_min`` [m] (sphere ``smallest``), the fastest initial speed ``v_start`` [m/s]
    (sphere ``fastest``), the largest speed over the run ``v_top`` [m/s] (gravity
    included) and ``gravity`` [m/s^2]."""

    steps: float
    frames: int
    duration: float
    step_fraction: float
    r_min: float
    smallest: int
    v_start: float
    fastest: int
    v_top: float
    gravity: tuple

    @property
    def by_gravity(self) -> bool:
        """Gravity adds more speed over the run than the fastest sphere starts with."""
        return self.v_top - self.v_start > self.v_start

    @property
    def by_frames(self) -> bool:
        """Frame ends make most of the steps."""
        return self.frames > 0.5 * self.steps

    def describe(self) -> str:
        """One line: the estimate and what it comes from."""
        speed = f"{self.v_top:.3g} m/s" + (", gravity included" if any(self.gravity) else "")
        return (f"about {self.steps:.1e} steps (fastest speed {speed}; a step moves a sphere "
                f"at most {self.step_fraction:g} x the smallest radius {self.r_min:.3g} m; "
                f"{self.frames} frames)")


def frame_count(duration: float, fps: float) -> int:
    """Frames of a run of ``duration`` [s] at ``fps``, both ends included: t = k / fps
    up to the duration, and one more at t = duration where the duration is not a whole
    number of frame intervals (frame_time)."""
    whole = _whole_frames(duration, fps)
    return whole + 1 + (1 if _off_grid(duration, fps, whole) else 0)


def frame_time(frame: int, duration: float, fps: float) -> float:
    """The time [s] of frame ``frame`` (from 0) of a run of ``duration`` [s] at ``fps``:
    frame / fps, the last frame of a duration off the frame grid at the duration."""
    return min(frame / fps, duration)


def _whole_frames(duration: float, fps: float) -> int:
    """Whole frame intervals in the duration (a product within 1e-9 of an integer counts
    as that integer)."""
    return int(math.floor(duration * fps + 1e-9))


def _off_grid(duration: float, fps: float, whole: int) -> bool:
    """The duration ends between frame times (beyond the rounding frame_count allows)."""
    return duration * fps - whole > 1e-9


def estimate(scene, duration: float, fps: float, step_fraction: float) -> Workload:
    """The work of a run of ``scene`` for ``duration`` [s] at ``fps`` frames per second
    (see the module docstring)."""
    speeds = np.sqrt(np.sum(np.square(scene.v), axis=1))
    fastest, smallest = int(np.argmax(speeds)), int(np.argmin(scene.radius))
    v0 = float(speeds[fastest])
    reach = step_fraction * float(scene.radius[smallest])
    g = math.hypot(*(float(c) for c in scene.gravity))
    t = np.linspace(0.0, duration, ESTIMATE_SAMPLES + 1)
    with np.errstate(over="ignore", invalid="ignore"):
        v = np.minimum(v0 + g * t, _speed_cap(scene, v0))
        rate = (v + np.hypot(v, math.sqrt(2.0 * g * reach))) / (2.0 * reach)   # steps/s
        flight = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))
    frames = frame_count(duration, fps)
    return Workload(steps=flight + frames, frames=frames, duration=duration,
                    step_fraction=step_fraction, r_min=reach / step_fraction,
                    smallest=smallest, v_start=v0, fastest=fastest, v_top=float(v[-1]),
                    gravity=tuple(float(c) for c in scene.gravity))


def _speed_cap(scene, v0: float) -> float:
    """Largest speed [m/s] gravity can bring a sphere of speed v0 to inside the box:
    unbounded when gravity pulls along a periodic axis."""
    periodic = np.array(scene.periodic)
    if np.any(scene.gravity[periodic] != 0.0):
        return math.inf
    return math.hypot(v0, fall_speed(scene.gravity, scene.box_lo, scene.box_hi))


def precision_problems(scene, precision: str, work: Workload) -> list:
    """What in ``scene`` ``precision`` ("f32" | "f64") cannot hold: speeds, gravity's
    speeds over the run, masses, radii too small to move in the box; [] if nothing."""
    problems = scene_precision_problems(scene, precision, work.step_fraction)
    if work.by_gravity:       # else the fastest sphere's own speed is the problem, if any
        problems.append(gravity_problem(precision, work.gravity, work.v_top))
    return [p for p in problems if p]


def refusal(work: Workload) -> str | None:
    """Why a run of this work is refused (above MAX_STEPS) and what to change, or None."""
    if work.steps <= MAX_STEPS:
        return None
    per_second = work.steps / work.duration if work.duration > 0 else math.inf
    if work.by_frames:
        cause = (f"{work.frames} frames ([run] fps x duration), and every frame ends a step",
                 "lower [run] fps (or --fps)")
    elif per_second * LONG_RUN_SECONDS <= MAX_STEPS:
        cause = (f"it lasts {work.duration:g} s of simulated time, at about "
                 f"{per_second:.1e} steps per simulated second",
                 "check that [run] duration is in simulated seconds")
    elif work.by_gravity:
        cause = (f"gravity {vector_text(work.gravity)} m/s^2 speeds spheres up to "
                 f"{work.v_top:.2g} m/s within {work.duration:g} s",
                 "check the units of [physics] gravity (m/s^2)")
    else:
        cause = (f"sphere {work.fastest} moves at {work.v_start:.3g} m/s",
                 f"check the speed of sphere {work.fastest} (v, m/s)")
    return (f"this run needs about {work.steps:.1e} steps, more than the {MAX_STEPS:.0e} "
            f"that real scenes stay below: {cause[0]}, while a step moves a sphere at most "
            f"step_fraction {work.step_fraction:g} x the smallest radius {work.r_min:.3g} m "
            f"(sphere {work.smallest}). {cause[1].capitalize()}, shorten the run "
            f"([run] duration or --duration) or raise [physics] step_fraction (at most 1); "
            f"or pass --force to run it anyway")


def model_step_seconds(n: int) -> float:
    """Seconds a step of n spheres takes on the reference machine (compiled)."""
    return REFERENCE_STEP_SECONDS + n * REFERENCE_SPHERE_STEP_SECONDS


def rough_duration(seconds: float) -> str:
    """An order of magnitude of a wall time: "about 3 s", "about 20 min", "about 2 days"."""
    if not math.isfinite(seconds):
        return "forever"
    for unit, size in (("years", 3.15e7), ("days", 86400.0), ("h", 3600.0), ("min", 60.0),
                       ("s", 1.0)):
        if seconds >= 2 * size:
            break
    value = seconds / size
    return f"about {float(f'{value:.2g}'):g} {unit}" if value < 1e4 else \
        f"about {value:.0e} {unit}"


def measure_step_seconds(sim, frame_dt: float, max_steps: float) -> tuple:
    """(seconds a step of ``sim`` takes once its kernels are compiled, seconds the
    measurement took): steps ``sim`` in batches (steps no longer than ``frame_dt`` [s]),
    at most about ``max_steps`` steps, then returns it to where it was
    (:meth:`Simulation.checkpoint` / ``restore``: the run's results do not change)."""
    saved = sim.checkpoint()
    start = time.perf_counter()
    try:
        per_step = _steady_step_seconds(sim, frame_dt, max_steps, start)
    finally:
        sim.restore(saved)
    return per_step, time.perf_counter() - start


def _steady_step_seconds(sim, frame_dt, max_steps, start):
    """Seconds per step of the faster of the last two batches once batches stop getting
    faster, after about ``max_steps`` steps, or CALIBRATION_MAX_SECONDS after the first
    batch; at least two batches (the first compiles the kernels, a resumed run's too)."""
    previous, done, clock = math.inf, 0, start
    while True:
        per_step, steps = _time_batch(sim, frame_dt, clock)
        done += steps
        settled = per_step * CALIBRATION_STEADY_RATIO >= previous
        later = previous < math.inf
        enough = later and (done >= max_steps or
                            time.perf_counter() - clock >= CALIBRATION_MAX_SECONDS)
        if settled or enough:
            return min(per_step, previous)
        if not later:       # the time limit counts from the end of the compiling batch
            clock = time.perf_counter()
        previous = per_step


def _time_batch(sim, frame_dt, start):
    """(seconds per step, steps) of one calibration batch."""
    t0, first = time.perf_counter(), sim.stats["steps"]
    while True:
        sim.advance(min(sim.max_step(), frame_dt))
        now, steps = time.perf_counter(), sim.stats["steps"] - first
        if (now - t0 >= CALIBRATION_BATCH_SECONDS and steps >= CALIBRATION_BATCH_STEPS) \
                or now - start >= CALIBRATION_MAX_SECONDS:
            return (now - t0) / max(steps, 1), steps
