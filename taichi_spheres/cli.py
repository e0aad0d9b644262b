"""Command line: ``taichi-spheres run SCENE``, ``info SCENE``, ``sweep SCENE`` and
``plot RUN.csv``.

Exit codes: 0 done, 1 some runs of a sweep failed (their rows say why), 2 bad input
(scene, options, output path, a CSV without the diagnostics columns, a run far beyond
what real scenes need: see workload.MAX_STEPS), 3 rendering or plotting not available,
130 interrupted (the frames or sweep rows written so far are kept).

Parsing the command line, ``--help`` and reading the scene do not import Taichi; the
engine is imported when ``info`` or ``run`` needs it. Details: docs/cli.md.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time

import numpy as np

from . import workload
from .interrupts import hold_interrupts
from .progress import STATUS_EVERY, Progress, status_reports
from .scene import Scene
from .scenefile import load_scene

EXIT_RUNS_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_NO_RENDER = 3
EXIT_INTERRUPTED = 130

DEFAULT_DURATION = 5.0
DEFAULT_FPS = 30.0
DEFAULT_SIZE = (640, 480)
DEFAULT_BACKGROUND = (0.08, 0.08, 0.10)
#: --compile auto: "fast" below this many spheres, else "optimized" (runtime.COMPILE_MODES;
#: taichi is imported only when a run starts).
#: Fast compiling saves ~10 s once and costs ~8 % per step (tools/compile_options.py:
#: CPU, one thread, N = 1e5; extrapolated here to 1e6 and 2 threads), so it wins unless
#: a run lasts minutes of stepping: ~600 steps of a million spheres, the length of a
#: 5 s default run of the bench's gas, on 2 cores. GPUs get the same choice, unmeasured.
AUTO_FAST_BELOW = 500_000
#: runtime.ARCHS and runtime.COMPILE_MODES, spelled out so that parsing the command line
#: does not import Taichi (tests/test_cli.py checks that they agree).
ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal")
COMPILE_CHOICES = ("auto", "fast", "optimized")
#: Taichi prints a banner on stdout when imported unless this environment variable is
#: "0"; the command line sets it (when unset) so that ``info`` prints only its report
#: (the run header names Taichi's version instead).
TAICHI_BANNER_ENV = "ENABLE_TAICHI_HEADER_PRINT"



def _scene_rows(values, ids, n) -> np.ndarray:
    """(n, 3) float32 rows in scene order: row ids[k] holds values[k]; NaN rows for the
    spheres that are gone (a sink took them out)."""
    out = np.full((n, 3), np.nan, dtype=np.float32)
    out[np.asarray(ids)] = values
    return out


def _kept_snapshots(path, frames) -> tuple:
    """([x], [v], [time]) of the first ``frames`` frames of an earlier run's .npz at
    ``path`` (a resumed run keeps them; _check_kept_snapshots checked them), empty
    lists for a run from the start."""
    if not frames:
        return [], [], []
    with np.load(path) as old:
        return list(old["x"][:frames]), list(old["v"][:frames]), list(old["time"][:frames])


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Appends "(default: X)" to an option's help unless the help already states its
    default or the option has none (None, False)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or action.default in (None, False, argparse.SUPPRESS):
            return text
        return super()._get_help_string(action)


def _size(text):
    try:
        w, h = (int(t) for t in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None
    if w <= 0 or h <= 0 or w % 16 or h % 16:
        raise argparse.ArgumentTypeError(f"size {w}x{h}: width and height must be positive "
                                         f"multiples of 16")
    return w, h


def _positive(kind):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not value > 0 or (isinstance(value, float) and not math.isfinite(value)):
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return value
    return parse


def build_parser():
    p = argparse.ArgumentParser(
        prog="taichi-spheres", formatter_class=_HelpFormatter,
        description="Hard-sphere simulations with exact rewind to contact, scene file in, "
                    "mp4 and diagnostics CSV out.")
    sub = p.add_subparsers(dest="command", required=True)
    _add_run_arguments(sub.add_parser("run", help="simulate a scene, write OUT.mp4 and OUT.csv",
                                      formatter_class=_HelpFormatter))
    info = sub.add_parser("info", formatter_class=_HelpFormatter,
                          help="validate a scene; show what it compiles in and the work a "
                               "run needs")
    info.add_argument("scene")
    info.add_argument("--arch", default="cpu", choices=ARCHS, help="where the kernels would run")
    info.add_argument("--calibrate", action="store_true",
                      help="time a few steps on this machine for the wall-time estimate "
                           "(compiles the kernels: seconds); without it the estimate uses "
                           "reference figures")
    _add_sweep_arguments(sub.add_parser(
        "sweep", formatter_class=_HelpFormatter,
        help="run a scene once per combination of parameter values (on Dask), one CSV row "
             "per run"))
    plot = sub.add_parser("plot", formatter_class=_HelpFormatter,
                          help="PNG plots of a run's diagnostics CSV: energy, collisions per "
                               "second, overlap against time (needs matplotlib)")
    plot.add_argument("csv", help="diagnostics CSV written by run (OUT.csv)")
    plot.add_argument("-o", "--output", default=None, metavar="PATH.png",
                      help="PNG to write (default: the CSV's path with .png)")
    return p


def _add_sweep_arguments(sweep):
    sweep.add_argument("scene", help="scene file (TOML)")
    sweep.add_argument("--set", action="append", default=[], metavar="KEY=V1,V2,...",
                       dest="grid", required=True,
                       help="values of one parameter (repeat for more: every combination "
                            "runs), e.g. restitution=0.5,0.7,0.9 or step_fraction=0.1,0.03; "
                            "keys: arguments of Scene.from_arrays (restitution, "
                            "wall_restitution, gravity=[0,0,-9.81], ...) and step_fraction, "
                            "max_sweeps, precision, fused")
    sweep.add_argument("--duration", type=_positive(float), default=None,
                       help=f"simulated seconds per run (default: the scene's [run] duration, "
                            f"else {DEFAULT_DURATION})")
    sweep.add_argument("--out", default=None, metavar="PATH.csv",
                       help="CSV written as runs finish (default: out/<scene name>-sweep.csv)")
    sweep.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="a Dask scheduler to run on (tcp://host:8786); default: a local "
                            "cluster of --workers processes")
    sweep.add_argument("--workers", type=_positive(int), default=None,
                       help="worker processes of the local cluster (default: one per core)")
    sweep.add_argument("--serial", action="store_true",
                       help="run here, one run after another, without Dask")
    sweep.add_argument("--threads", type=_positive(int), default=1,
                       help="Taichi CPU threads per run")
    sweep.add_argument("--arch", default="cpu", choices=ARCHS, help="where the kernels run")
    sweep.add_argument("--precision", default=None, choices=["f32", "f64"],
                       help="default: the scene's, else the arch's")
    sweep.add_argument("--compile", default="auto", choices=COMPILE_CHOICES,
                       help="how Taichi compiles the kernels (as for run)")
    sweep.add_argument("--quiet", action="store_true", help="no line per finished run")


def _add_run_arguments(run):
    run.add_argument("scene", help="scene file (TOML)")
    run.add_argument("-o", "--output", default=None,
                     help="output video path (default: out/<scene name>.mp4)")
    run.add_argument("--arch", default="cpu", choices=ARCHS, help="where the kernels run")
    run.add_argument("--precision", default=None, choices=["f32", "f64"],
                     help="default: the scene's, else f64 on cpu/cuda, f32 on vulkan/metal")
    run.add_argument("--duration", type=_positive(float), default=None,
                     help=f"simulated seconds (default: the scene's [run] duration, "
                          f"else {DEFAULT_DURATION})")
    run.add_argument("--fps", type=_positive(float), default=None,
                     help=f"frames per simulated second (default: scene's, else {DEFAULT_FPS:g})")
    run.add_argument("--size", type=_size, default=None,
                     help="frame size WxH, multiples of 16 (default: scene's, else 640x480)")
    run.add_argument("--no-video", action="store_true", help="diagnostics only, no rendering")
    run.add_argument("--npz", action="store_true",
                     help="also write OUT.npz with positions and velocities of every frame")
    run.add_argument("--trajectory", default=None, metavar="PATH.gsd",
                     help="also write a GSD trajectory (HOOMD schema: OVITO, freud, "
                          "MDAnalysis read it), one frame per video frame or --every")
    run.add_argument("--every", type=_positive(int), default=None, metavar="STEPS",
                     help="write a trajectory frame every STEPS steps instead of one per "
                          "video frame")
    run.add_argument("--checkpoint-every", type=_positive(int), default=None, metavar="FRAMES",
                     help="write OUT.ckpt.npz every FRAMES frames (overwritten each time)")
    run.add_argument("--resume", default=None, metavar="CHECKPOINT",
                     help="continue a run from its OUT.ckpt.npz; the result is bit-identical "
                          "to an uninterrupted run with the same options")
    run.add_argument("--threads", type=_positive(int), default=None,
                     help="Taichi CPU threads (default: Taichi's, all cores)")
    run.add_argument("--fused", action="store_true",
                     help="run each step as one fused kernel (CPU, below 3,000 spheres): "
                          "faster steps after a one-off compile of 10-60 s; same results")
    run.add_argument("--compile", default="auto", choices=COMPILE_CHOICES,
                     help="how Taichi compiles the kernels: fast (~3x shorter compile, steps "
                          "~8%% slower, same results) or optimized; auto: "
                          f"TAICHI_SPHERES_COMPILE if set, else fast below {AUTO_FAST_BELOW:,} "
                          "spheres")
    run.add_argument("--force", action="store_true",
                     help=f"run even when the estimated work is beyond what real scenes need "
                          f"(more than {workload.MAX_STEPS:.0e} steps)")
    run.add_argument("--quiet", action="store_true",
                     help="no progress bar (the bar is shown only on a terminal; status lines "
                          "still come every --status-every seconds and on SIGUSR1)")
    run.add_argument("--status-every", type=_positive(float), default=STATUS_EVERY,
                     metavar="SECONDS",
                     help="print a status line when none was printed for this long")


def main(argv=None):
    """The ``taichi-spheres`` command; its exit status. Output piped into a reader that
    stops early (``taichi-spheres info SCENE | head``) ends it quietly with status 1."""
    try:
        return _main(argv)
    except BrokenPipeError:
        # stdout is gone: point it at /dev/null so that Python's exit flush cannot fail
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_RUNS_FAILED


def _main(argv):
    args = build_parser().parse_args(argv)
    os.environ.setdefault(TAICHI_BANNER_ENV, "0")
    if args.command == "plot":
        return cmd_plot(args)
    try:
        scene = load_scene(args.scene)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.command == "info":
        return cmd_info(scene, args)
    if args.command == "sweep":
        return cmd_sweep(scene, args)
    return cmd_run(scene, args)


def cmd_plot(args):
    """Write the PNG plots of a diagnostics CSV (plot.py); 2 for a bad CSV or output
    path, 3 without matplotlib."""
    from .plot import PlotUnavailable, plot_diagnostics
    try:
        out = plot_diagnostics(args.csv, args.output)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except PlotUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_NO_RENDER
    print(f"wrote {out}", file=sys.stderr)
    return 0


def compile_mode(choice: str, n: int) -> str:
    """The runtime compile mode for --compile ``choice`` and a scene of n spheres."""
    from . import runtime
    if choice != "auto":
        return choice
    return runtime.compile_mode_from_env("fast" if n < AUTO_FAST_BELOW else "optimized")


def _settings(scene: Scene):
    return (scene.meta.get("run", {}), scene.meta.get("physics", {}),
            scene.meta.get("render", {}))


def _precision(scene: Scene, asked, arch) -> str:
    """--precision, else the scene's [physics] precision, else the arch's default."""
    from . import runtime
    return asked or scene.meta.get("physics", {}).get("precision") or \
        runtime.default_precision(arch)


def check_work(scene: Scene, precision, duration, fps, step_fraction, force=False):
    """The Workload of a run; ValueError naming the sphere or setting at fault when the
    precision cannot hold the scene, or (unless ``force``) the run is beyond MAX_STEPS."""
    work = workload.estimate(scene, duration, fps, step_fraction)
    problems = workload.precision_problems(scene, precision, work)
    if problems:
        raise ValueError("; ".join(problems))
    refused = workload.refusal(work)
    if refused and not force:
        raise ValueError(refused)
    return work


def cmd_info(scene: Scene, args):
    from . import runtime
    from .config import DEFAULT
    from .contacts.shock import shock_compiled
    from .grid import GridGeometry
    from .simulation import estimate_field_bytes, rest_speed_for, scene_simulation_settings
    from .state import Features
    run, _, render = _settings(scene)
    fraction, _, precision = scene_simulation_settings(scene)
    geom = GridGeometry.for_scene(scene, fraction)
    precision = precision or runtime.default_precision(args.arch)
    rest_speed = rest_speed_for(scene, fraction)
    features = Features.from_scene(scene, rest_speed)
    memory = estimate_field_bytes(scene, precision, fraction)
    duration, fps = run.get("duration", DEFAULT_DURATION), run.get("fps", DEFAULT_FPS)
    print(f"scene: {scene.name} ({scene.meta.get('source', '')})")
    print(f"spheres: {scene.n}, radius {scene.radius.min():g}..{scene.radius.max():g} m, "
          f"mass {scene.mass.min():g}..{scene.mass.max():g} kg")
    print(f"box: {scene.box_lo.tolist()} .. {scene.box_hi.tolist()} m, "
          f"periodic {list(scene.periodic)}")
    print(f"gravity: {scene.gravity.tolist()} m/s^2, restitution {scene.restitution:g} "
          f"({scene.restitution_model}), wall restitution {scene.wall_restitution:g}, "
          f"impact speed {rest_speed:.3g} m/s")
    print(f"run: duration {duration:g} s at {fps:g} fps; precision {precision}; "
          f"step_fraction {fraction:g}")
    print(f"grid: {geom.dims[0]}x{geom.dims[1]}x{geom.dims[2]} cells, {len(geom.colours)} colours")
    print("compiled in:")
    for line in features.describe(shock_compiled(features, DEFAULT.physics)):
        print(f"  {line}")
    print(f"schedule ({args.arch}):")
    for line in schedule_for(scene, geom, args.arch, getattr(args, "fused", False)).describe():
        print(f"  {line}")
    print(f"device memory: about {memory / 2**20:.2f} MiB ({memory / scene.n:.0f} B per sphere, "
          f"grid included)")
    return _print_info_work(scene, args, precision, duration, fps, fraction)


def schedule_for(scene: Scene, geom, arch: str, fused: bool):
    """The engine.Schedule a Simulation of ``scene`` on ``arch`` takes (default options),
    without initialising Taichi ('gpu' counts as a GPU)."""
    from .config import DEFAULT
    from .engine import Schedule
    from .simulation import _keeps_near_lists
    perf = DEFAULT.performance
    return Schedule.plan(scene.n, arch == "cpu", _keeps_near_lists(scene, geom, perf), fused,
                         perf)


def _print_info_work(scene, args, precision, duration, fps, fraction):
    """The work lines of ``info``; exit status 2 when the precision cannot hold the scene."""
    work = workload.estimate(scene, duration, fps, fraction)
    print(f"work: {work.describe()}")
    problems = workload.precision_problems(scene, precision, work)
    if problems:
        print(f"error: {'; '.join(problems)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    refused = workload.refusal(work)
    if refused:
        print(f"refused: `run` refuses this without --force: {refused}")
        return 0
    if args.calibrate:
        per_step = _calibrate_info(scene, args.arch, precision, fraction, fps, work)
        print(f"wall time: {_timing(per_step, work)} measured on this machine")
    else:
        per_step = workload.model_step_seconds(scene.n)
        print(f"wall time: {_timing(per_step, work)} on the reference CPU, for free flight "
              f"(dense piles step slower; --calibrate times this machine)")
    return 0


def _calibrate_info(scene, arch, precision, fraction, fps, work):
    """Seconds a step takes on this machine, timed on a Simulation built for it."""
    from . import runtime
    from .simulation import Simulation
    runtime.ensure(arch, precision, compile=compile_mode("auto", scene.n))
    sim = Simulation(scene, arch=arch, precision=precision, step_fraction=fraction)
    return workload.measure_step_seconds(sim, 1.0 / fps, work.steps)[0]


def _timing(per_step, work) -> str:
    return (f"{workload.rough_duration(per_step * work.steps)} of stepping "
            f"({per_step * 1e3:.3g} ms a step)")


@dataclasses.dataclass
class RunSettings:
    """What a run does, from the command line and the scene file: duration [s], fps,
    frame size, output paths (video, csv, npz, checkpoint) and switches."""

    duration: float
    fps: float
    size: tuple
    video_path: str
    npz: bool
    checkpoint_every: int | None
    step_fraction: float
    max_sweeps: int
    trajectory: str | None = None
    trajectory_every: int | None = None

    @property
    def stem(self):
        return os.path.splitext(self.video_path)[0]

    @property
    def csv_path(self):
        return self.stem + ".csv"

    @property
    def npz_path(self):
        return self.stem + ".npz"

    @property
    def ckpt_path(self):
        return self.stem + ".ckpt.npz"

    @property
    def frames(self):
        return workload.frame_count(self.duration, self.fps)


def run_settings(scene: Scene, args) -> RunSettings:
    from .simulation import scene_simulation_settings
    run, _, render = _settings(scene)
    fraction, sweeps, _ = scene_simulation_settings(scene)
    output = scene.meta.get("output", {})
    video_path = args.output or output.get("video")
    if video_path is None:
        video_path = os.path.join("out", f"{scene.name}.mp4")
        os.makedirs("out", exist_ok=True)
    return RunSettings(
        duration=args.duration or run.get("duration", DEFAULT_DURATION),
        fps=args.fps or run.get("fps", DEFAULT_FPS),
        size=args.size or (render.get("width", DEFAULT_SIZE[0]),
                           render.get("height", DEFAULT_SIZE[1])),
        video_path=video_path, npz=args.npz or output.get("snapshots", False),
        checkpoint_every=args.checkpoint_every or output.get("checkpoint_every"),
        step_fraction=fraction, max_sweeps=sweeps,
        trajectory=args.trajectory or output.get("trajectory"),
        trajectory_every=args.every or output.get("trajectory_every"))


def _check_outputs(settings: RunSettings, no_video):
    """ValueError before simulating when an output cannot be written."""
    from .output import check_writable
    if not settings.video_path.lower().endswith(".mp4"):
        raise ValueError(f"output must end in .mp4, got {settings.video_path}")
    if settings.trajectory is not None and not settings.trajectory.lower().endswith(".gsd"):
        raise ValueError(f"--trajectory must end in .gsd, got {settings.trajectory}")
    if settings.trajectory_every and settings.trajectory is None:
        raise ValueError("--every (steps between trajectory frames) needs --trajectory PATH.gsd")
    for path in [settings.csv_path] + ([] if no_video else [settings.video_path]) + \
            ([settings.npz_path] if settings.npz else []) + \
            ([settings.trajectory] if settings.trajectory else []):
        check_writable(path)


def _start_simulation(scene: Scene, settings: RunSettings, args):
    """(Simulation, first frame, Workload), after checking outputs, precision and work;
    ValueError or RuntimeError for bad input."""
    from . import checkpoint, runtime
    from .simulation import Simulation
    _check_outputs(settings, args.no_video)
    precision = _precision(scene, args.precision, args.arch)
    work = check_work(scene, precision, settings.duration, settings.fps,
                      settings.step_fraction, force=args.force)
    runtime.ensure(args.arch, precision, args.threads,
                   compile=compile_mode(args.compile, scene.n))
    sim = Simulation(scene, arch=args.arch, precision=precision,
                     step_fraction=settings.step_fraction, max_sweeps=settings.max_sweeps,
                     fused=args.fused, threads=args.threads)
    start_frame = 0
    if args.resume:
        frame = checkpoint.load(args.resume, sim, scene, settings.fps)
        _check_resumed_frame(args.resume, frame, sim.time, settings)
        start_frame = frame + 1
        if settings.npz:
            _check_kept_snapshots(settings.npz_path, start_frame, scene.n, settings)
    return sim, start_frame, work


def _check_resumed_frame(path, frame, time_, settings: RunSettings) -> None:
    """ValueError unless checkpoint ``path``'s frame, taken at ``time_`` [s], is a frame
    of this run before its last, at that time (a checkpoint on the extra last frame of
    a duration off the frame grid is not a frame of a longer run)."""
    if frame + 1 >= settings.frames:
        raise ValueError(f"checkpoint {path} was taken at frame {frame} (t = {time_:g} s), "
                         f"at or after the end of this run ({settings.frames} frames over "
                         f"{settings.duration:g} s): nothing is left to run")
    expected = workload.frame_time(frame, settings.duration, settings.fps)
    if time_ != expected:
        raise ValueError(f"checkpoint {path} was taken at t = {time_:.17g} s, not at frame "
                         f"{frame} of this run (t = {expected:.17g} s at {settings.fps:g} "
                         f"fps): resume with the duration of the run that wrote it")


def _check_kept_snapshots(path, frames, n, settings: RunSettings) -> None:
    """ValueError unless ``path`` holds the first ``frames`` frames of this run's
    snapshots (n spheres each, at this run's frame times), which a resumed --npz run
    keeps."""
    hint = "resume without --npz, or start the run again"
    if not os.path.exists(path):
        raise ValueError(f"--npz: {path} does not exist, so the frames before the "
                         f"checkpoint cannot be kept: {hint}")
    try:
        with np.load(path) as old:
            shape, times = old["x"].shape, np.array(old["time"][:frames])
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"--npz: cannot read {path}: {exc}") from None
    want = [workload.frame_time(k, settings.duration, settings.fps) for k in range(frames)]
    if len(shape) != 3 or shape[1] != n or len(times) < frames or \
            not np.array_equal(times, np.array(want, dtype=times.dtype)):
        raise ValueError(f"--npz: {path} does not hold this run's first {frames} frames of "
                         f"{n} spheres: {hint}")


def _make_renderer(scene: Scene, settings: RunSettings):
    """The offscreen renderer for the scene's [render] settings (RenderUnavailable)."""
    from .render import Renderer, palette
    render = scene.meta.get("render", {})
    colours = palette(scene.meta.get("groups", np.zeros(scene.n, dtype=np.int64)))
    table = scene.meta.get("group_colours")
    groups = scene.meta.get("groups")
    if table is not None and groups is not None and len(table):
        given = table[groups]
        colours = np.where(given[:, :1] >= 0, given, colours).astype(np.float32)
    camera = {k: render[f"camera_{k}"] for k in ("position", "lookat") if f"camera_{k}" in render}
    if "fov" in render:
        camera["fov"] = render["fov"]
    return Renderer(scene, size=settings.size, camera=camera,
                    colours=render.get("colours", "group"), colour_table=colours,
                    background=render.get("background", DEFAULT_BACKGROUND))


def _print_header(scene, settings, sim, renderer, work):
    import taichi as ti
    rt = sim.runtime
    print(f"taichi-spheres: {scene.name}, {scene.n} spheres, {settings.duration:g} s at "
          f"{settings.fps:g} fps ({settings.frames} frames); arch {rt.arch} (Taichi "
          f"{'.'.join(map(str, ti.__version__))} on {rt.actual}), {sim.precision}, "
          f"{rt.compile} compile; "
          f"renderer: {'none (--no-video)' if renderer is None else 'GGUI offscreen'}",
          file=sys.stderr)
    print(f"work: {work.describe()}" + ("; above the limit, run with --force"
                                       if workload.refusal(work) else ""), file=sys.stderr)


def _print_timing(sim, settings, work, start_frame):
    """Time a few steps (compiling the kernels on the way) and print the wall-time estimate."""
    left = work.steps * (1.0 - start_frame / settings.frames)
    per_step, took = workload.measure_step_seconds(sim, 1.0 / settings.fps, left)
    print(f"timing: {per_step * 1e3:.3g} ms a step (measured in {took:.1f} s, compiling "
          f"included): {workload.rough_duration(per_step * left)} of stepping, plus "
          f"writing {settings.frames - start_frame} frames", file=sys.stderr)


class RunOutputs:
    """The files a run writes frame by frame: video, diagnostics CSV, snapshots, GSD
    trajectory, checkpoint. A frame goes to all of them or (Ctrl-C) to none."""

    def __init__(self, scene, settings: RunSettings, renderer, start_frame, sim):
        from . import checkpoint
        from .output import DiagnosticsWriter, VideoWriter
        self.scene, self.settings, self.renderer = scene, settings, renderer
        self.earlier = checkpoint.set_aside(settings.video_path) \
            if renderer is not None and start_frame else None
        self.video = VideoWriter(settings.video_path, settings.fps) if renderer else None
        self.diag = DiagnosticsWriter(settings.csv_path, scene.gravity, keep_frames=start_frame)
        self.trajectory, self.step_frames = _trajectory_outputs(settings, sim, start_frame)
        self.snaps = _kept_snapshots(settings.npz_path, start_frame) if settings.npz \
            else ([], [], [])
        self.render_seconds = 0.0
        self.start_frame = start_frame

    def copy_earlier_video(self):
        from . import checkpoint
        if self.earlier:     # (interrupted here, the next --resume starts from it again)
            checkpoint.copy_video_prefix(self.earlier, self.video, self.start_frame)

    def write(self, frame, sim):
        """Render frame ``frame`` of ``sim``, then write it to every output with Ctrl-C
        held, so that an interrupt leaves all files at the same frame."""
        from . import checkpoint
        st = sim.state()
        t0 = time.perf_counter()
        rgb = self.renderer.frame(st, sim.sphere_ids) if self.video is not None else None
        with hold_interrupts():
            self.diag.write(frame, st, sim.stats)
            if self.settings.npz:
                n = self.scene.n
                for store, value in zip(self.snaps, (_scene_rows(st.x, sim.sphere_ids, n),
                                                     _scene_rows(st.v, sim.sphere_ids, n),
                                                     st.time)):
                    store.append(value)
            if rgb is not None:
                self.video.write(rgb)
                self.render_seconds += time.perf_counter() - t0
            self._write_trajectory(sim)
            every = self.settings.checkpoint_every
            if every and (frame + 1) % every == 0:
                checkpoint.save(self.settings.ckpt_path, sim, self.scene, frame,
                                self.settings.fps)

    def _write_trajectory(self, sim):
        """One GSD frame per video frame, or the frame --every steps made due."""
        if self.step_frames is not None:
            self.step_frames.flush()
        elif self.trajectory is not None:
            self.trajectory.append(sim)

    def close(self):
        """Close every file (Ctrl-C held meanwhile) and say which were written."""
        s = self.settings
        with hold_interrupts():
            if self.video is not None:
                self.video.close()
            self.diag.close()
            if self.step_frames is not None:
                self.step_frames.detach()
            if self.trajectory is not None:
                self.trajectory.close()
            if s.npz and self.snaps[0]:
                np.savez_compressed(s.npz_path, x=np.stack(self.snaps[0]),
                                    v=np.stack(self.snaps[1]), time=np.array(self.snaps[2]),
                                    radius=self.scene.radius, mass=self.scene.mass)
            if self.renderer is not None:
                self.renderer.close()
            written = [p for p, on in ((s.video_path, self.video is not None), (s.csv_path, True),
                                       (s.npz_path, s.npz and bool(self.snaps[0])),
                                       (s.trajectory, self.trajectory is not None),
                                       (s.ckpt_path, bool(s.checkpoint_every))) if on]
            extra = f"; {self.trajectory.frames} trajectory frames" \
                if self.step_frames is not None else ""
            print(f"wrote {', '.join(written)} ({self.diag.rows} frames{extra})",
                  file=sys.stderr)


def _trajectory_outputs(settings: RunSettings, sim, start_frame):
    """(GSDWriter or None, StepFrames or None) for --trajectory and --every; a resumed
    run keeps the frames written up to its checkpoint."""
    if settings.trajectory is None:
        return None, None
    from .trajectory import GSDWriter, StepFrames
    writer = GSDWriter(settings.trajectory,
                       keep_until_step=sim.stats["steps"] if start_frame else None)
    if not settings.trajectory_every:
        return writer, None
    return writer, StepFrames(sim, writer, settings.trajectory_every)


def cmd_run(scene: Scene, args):
    settings = run_settings(scene, args)
    progress = Progress(settings.duration, settings.frames, args.quiet, args.status_every)
    with status_reports(progress):
        try:
            sim, start_frame, work = _start_simulation(scene, settings, args)
        except (ValueError, RuntimeError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        renderer = None
        if not args.no_video:
            from .render import RenderUnavailable
            try:
                renderer = _make_renderer(scene, settings)
            except RenderUnavailable as exc:
                print(f"error: {exc}", file=sys.stderr)
                return EXIT_NO_RENDER
        _print_header(scene, settings, sim, renderer, work)
        try:
            _print_timing(sim, settings, work, start_frame)
        except KeyboardInterrupt:
            if renderer is not None:
                renderer.close()
            print("\ninterrupted before the first frame; nothing written", file=sys.stderr)
            return EXIT_INTERRUPTED
        progress.steps = work.steps
        progress.attach(sim, start_frame)
        outputs = RunOutputs(scene, settings, renderer, start_frame, sim)
        status = _run_frames(sim, outputs, progress, settings, start_frame)
    _print_summary(sim, outputs.render_seconds)
    return status


def _run_frames(sim, outputs: RunOutputs, progress, settings, start_frame):
    """Step frame by frame, writing each; the exit status (130 when interrupted)."""
    status, frame = 0, start_frame - 1
    try:
        outputs.copy_earlier_video()
        for frame in range(start_frame, settings.frames):
            sim.advance_to(workload.frame_time(frame, settings.duration, settings.fps))
            outputs.write(frame, sim)
            progress.frame_done(frame, final=frame == settings.frames - 1)
    except KeyboardInterrupt:
        status = EXIT_INTERRUPTED
        progress.close()
        print(f"\ninterrupted at frame {frame} (t = {sim.time:.4g} s)"
              + (f"; continue with --resume {settings.ckpt_path}"
                 if settings.checkpoint_every else ""), file=sys.stderr)
    except Exception as exc:   # keep what was written, then re-raise after closing
        progress.close()
        print(f"\nerror at frame {frame}: {exc!r}", file=sys.stderr)
        raise
    finally:
        try:
            outputs.close()
        except KeyboardInterrupt:
            status = EXIT_INTERRUPTED
    return status


def _print_summary(sim, render_seconds):
    """The run's last line (stderr): wall and simulated time, steps (and the substeps
    they ran in, where Rules.substeps split them: the work estimate counts those),
    collisions, overlap, rendering time."""
    st = sim.stats
    substeps = st.get("substeps", st["steps"])
    steps = f"{st['steps']} steps" + (f" in {substeps} substeps" if substeps != st["steps"]
                                      else "")
    print(f"simulation: {sim.sim_seconds:.2f} s wall for {sim.time:g} s simulated, "
          f"{steps}, {st['pair_collisions']} pair + {st['wall_collisions']} wall "
          f"collisions, max overlap {st['max_overlap']:.2e}, unresolved {st['unresolved']}; "
          f"rendering: {render_seconds:.2f} s", file=sys.stderr)


def split_values(text: str) -> list:
    """'0.5,0.7' -> [0.5, 0.7]; each value is read as TOML (numbers, true/false, arrays
    such as [0, 0, -9.81], quoted strings), else taken as a bare string ('smid')."""
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib
    items, depth, start = [], 0, 0
    for k, c in enumerate(text + ","):
        depth += (c == "[") - (c == "]")
        if c == "," and depth == 0:
            items.append(text[start:k].strip())
            start = k + 1
    values = []
    for item in items:
        if not item:
            raise ValueError(f"empty value in {text!r}")
        try:
            values.append(tomllib.loads(f"v = {item}")["v"])
        except tomllib.TOMLDecodeError:
            values.append(item)
    return values


def sweep_grid(settings: list) -> dict:
    """{key: values} of the --set options (ValueError naming a malformed one)."""
    grid = {}
    for text in settings:
        key, sep, values = text.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set {text!r}: write KEY=VALUE1,VALUE2,...")
        if key.strip() in grid:
            raise ValueError(f"--set {key.strip()} given twice: list all values in one --set")
        try:
            grid[key.strip()] = split_values(values)
        except ValueError as exc:
            raise ValueError(f"--set {key.strip()}: {exc}") from None
    return grid


def cmd_sweep(scene: Scene, args):
    """Run the grid of --set values on Dask (or --serial); the CSV is written as runs end."""
    from .sweeps import sweep
    run = scene.meta.get("run", {})
    out = args.out or os.path.join("out", f"{scene.name}-sweep.csv")
    try:
        grid = sweep_grid(args.grid)
        if args.out is None:
            os.makedirs("out", exist_ok=True)
        rows = sweep(scene, grid, args.duration or run.get("duration", DEFAULT_DURATION),
                     client=args.scheduler, serial=args.serial, workers=args.workers,
                     threads=args.threads, arch=args.arch, precision=args.precision,
                     compile=args.compile, out=out, progress=not args.quiet)
    except (ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"\ninterrupted; the runs that finished are in {out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    failed = sum(row["error"] is not None for row in rows)
    print(f"wrote {out} ({len(rows)} runs, {failed} failed)", file=sys.stderr)
    return EXIT_RUNS_FAILED if failed else 0


if __name__ == "__main__":
    sys.exit(main())
