"""Command line: ``taichi-spheres run SCENE`` and ``taichi-spheres info SCENE``.

Exit codes: 0 done, 2 bad input (scene, options, output path), 3 rendering not
available, 130 interrupted (the frames written so far are kept, playable).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from .interrupts import hold_interrupts
from .scene import Scene
from .scenefile import load_scene

EXIT_BAD_INPUT = 2
EXIT_NO_RENDER = 3
EXIT_INTERRUPTED = 130

DEFAULT_DURATION = 5.0
DEFAULT_FPS = 30.0
DEFAULT_SIZE = (640, 480)
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
        prog="taichi-spheres", formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        description="Hard-sphere simulations with exact rewind to contact, scene file in, "
                    "mp4 and diagnostics CSV out.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate a scene, write OUT.mp4 and OUT.csv",
                         formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    run.add_argument("scene", help="scene file (TOML)")
    run.add_argument("-o", "--output", default=None,
                     help="output video path (default: out/<scene name>.mp4)")
    run.add_argument("--arch", default="cpu", choices=ARCHS)
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
    run.add_argument("--checkpoint-every", type=_positive(int), default=None, metavar="FRAMES",
                     help="write OUT.ckpt.npz every FRAMES frames (overwritten each time)")
    run.add_argument("--resume", default=None, metavar="CHECKPOINT",
                     help="continue a run from its OUT.ckpt.npz; the result is bit-identical "
                          "to an uninterrupted run with the same options")
    run.add_argument("--fused", action="store_true",
                     help="run each step as one fused kernel (CPU, below 3,000 spheres): "
                          "faster steps after a one-off compile of 10-60 s; same results")
    run.add_argument("--compile", default="auto", choices=COMPILE_CHOICES,
                     help="how Taichi compiles the kernels: fast (~3x shorter compile, steps "
                          "~8%% slower, same results) or optimized; auto: "
                          f"TAICHI_SPHERES_COMPILE if set, else fast below {AUTO_FAST_BELOW:,} "
                          "spheres")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    info = sub.add_parser("info", help="validate a scene and show what it compiles in")
    info.add_argument("scene")
    info.add_argument("--arch", default="cpu", choices=ARCHS)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        scene = load_scene(args.scene)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.command == "info":
        return cmd_info(scene, args)
    return cmd_run(scene, args)


def compile_mode(choice: str, n: int) -> str:
    """The runtime compile mode for --compile ``choice`` and a scene of n spheres."""
    from . import runtime
    if choice != "auto":
        return choice
    return runtime.compile_mode_from_env("fast" if n < AUTO_FAST_BELOW else "optimized")


def _settings(scene: Scene):
    return (scene.meta.get("run", {}), scene.meta.get("physics", {}),
            scene.meta.get("render", {}))


def cmd_info(scene: Scene, args):
    from . import runtime
    from .grid import GridGeometry
    from .simulation import DEFAULT_STEP_FRACTION, estimate_field_bytes, rest_speed_for
    from .state import Features
    run, physics, render = _settings(scene)
    fraction = physics.get("step_fraction", DEFAULT_STEP_FRACTION)
    geom = GridGeometry.for_scene(scene, fraction)
    precision = physics.get("precision") or runtime.default_precision(args.arch)
    rest_speed = rest_speed_for(scene, fraction)
    features = Features.from_scene(scene, rest_speed)
    memory = estimate_field_bytes(scene, precision, fraction)
    print(f"scene: {scene.name} ({scene.meta.get('source', '')})")
    print(f"spheres: {scene.n}, radius {scene.radius.min():g}..{scene.radius.max():g} m, "
          f"mass {scene.mass.min():g}..{scene.mass.max():g} kg")
    print(f"box: {scene.box_lo.tolist()} .. {scene.box_hi.tolist()} m, "
          f"periodic {list(scene.periodic)}")
    print(f"gravity: {scene.gravity.tolist()} m/s^2, restitution {scene.restitution:g} "
          f"({scene.restitution_model}), wall restitution {scene.wall_restitution:g}, "
          f"rest speed {rest_speed:.3g} m/s")
    print(f"run: duration {run.get('duration', DEFAULT_DURATION):g} s at "
          f"{run.get('fps', DEFAULT_FPS):g} fps; precision {precision}; step_fraction {fraction:g}")
    print(f"grid: {geom.dims[0]}x{geom.dims[1]}x{geom.dims[2]} cells, {len(geom.colours)} colours")
    print("compiled in:")
    for line in features.describe():
        print(f"  {line}")
    print(f"device memory: about {memory / 2**20:.2f} MiB ({memory / scene.n:.0f} B per sphere, "
          f"grid included)")
    return 0


class Progress:
    """One status line on stderr: simulated time, steps, collisions, ETA."""

    def __init__(self, total_frames, duration, quiet=False):
        self.total = total_frames
        self.duration = duration
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.last = -1.0
        self.last_tenth = -1

    def update(self, frame, sim, final=False):
        if self.quiet:
            return
        now = time.perf_counter()
        done = (frame + 1) / self.total
        tenth = int(done * 10)
        if not final and (self.tty and now - self.last < 0.2 or
                          not self.tty and tenth == self.last_tenth):
            return
        self.last, self.last_tenth = now, tenth
        elapsed = now - self.t0
        eta = elapsed / done * (1 - done) if done > 0 else float("nan")
        st = sim.stats
        bar = "#" * int(24 * done)
        line = (f"[{bar:<24}] t={sim.time:.3f}/{self.duration:g} s  steps={st['steps']}  "
                f"collisions={st['pair_collisions']}+{st['wall_collisions']} wall  "
                f"ETA {eta:5.1f} s")
        end = "\n" if final or not self.tty else ""
        print(("\r" if self.tty else "") + line, end=end, file=sys.stderr, flush=True)


def cmd_run(scene: Scene, args):
    from . import checkpoint
    from .output import DiagnosticsWriter, VideoWriter, check_writable
    from .simulation import DEFAULT_MAX_SWEEPS, DEFAULT_STEP_FRACTION, Simulation
    run, physics, render = _settings(scene)
    duration = args.duration or run.get("duration", DEFAULT_DURATION)
    fps = args.fps or run.get("fps", DEFAULT_FPS)
    size = args.size or (render.get("width", DEFAULT_SIZE[0]), render.get("height", DEFAULT_SIZE[1]))
    output = scene.meta.get("output", {})
    video_path = args.output or output.get("video")
    args.npz = args.npz or output.get("snapshots", False)
    args.checkpoint_every = args.checkpoint_every or output.get("checkpoint_every")
    if video_path is None:
        video_path = os.path.join("out", f"{scene.name}.mp4")
        os.makedirs("out", exist_ok=True)
    stem = os.path.splitext(video_path)[0]
    csv_path, npz_path = stem + ".csv", stem + ".npz"
    try:
        if not video_path.lower().endswith(".mp4"):
            raise ValueError(f"output must end in .mp4, got {video_path}")
        for path in [csv_path] + ([] if args.no_video else [video_path]) + \
                ([npz_path] if args.npz else []):
            check_writable(path)
        precision = args.precision or physics.get("precision")
        from . import runtime
        runtime.ensure(args.arch, precision, compile=compile_mode(args.compile, scene.n))
        sim = Simulation(scene, arch=args.arch,
                         precision=precision,
                         step_fraction=physics.get("step_fraction", DEFAULT_STEP_FRACTION),
                         max_sweeps=physics.get("max_sweeps", DEFAULT_MAX_SWEEPS),
                         fused=args.fused)
        start_frame = 0
        if args.resume:
            start_frame = checkpoint.load(args.resume, sim, scene, fps) + 1
    except (ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    ckpt_path = stem + ".ckpt.npz"
    renderer = None
    if not args.no_video:
        from .render import RenderUnavailable, Renderer, palette
        colours = palette(scene.meta.get("groups", np.zeros(scene.n, dtype=np.int64)))
        table = scene.meta.get("group_colours")
        groups = scene.meta.get("groups")
        if table is not None and groups is not None and len(table):
            given = table[groups]
            colours = np.where(given[:, :1] >= 0, given, colours).astype(np.float32)
        camera = {k: render[f"camera_{k}"] for k in ("position", "lookat") if f"camera_{k}" in render}
        if "fov" in render:
            camera["fov"] = render["fov"]
        try:
            renderer = Renderer(scene, size=size, camera=camera,
                                colours=render.get("colours", "group"), colour_table=colours,
                                background=render.get("background", (0.08, 0.08, 0.10)))
        except RenderUnavailable as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_NO_RENDER
    frames = int(math.floor(duration * fps + 1e-9)) + 1
    rt = sim.runtime
    print(f"taichi-spheres: {scene.name}, {scene.n} spheres, {duration:g} s at {fps:g} fps "
          f"({frames} frames); arch {rt.arch} (Taichi {rt.actual}), {sim.precision}, "
          f"{rt.compile} compile; "
          f"renderer: {'none (--no-video)' if renderer is None else 'GGUI offscreen'}",
          file=sys.stderr)
    progress = Progress(frames, duration, args.quiet)
    earlier = checkpoint.set_aside(video_path) if renderer is not None and start_frame else None
    video = VideoWriter(video_path, fps) if renderer is not None else None
    diag = DiagnosticsWriter(csv_path, scene.gravity, keep_frames=start_frame)
    snaps_x, snaps_v, snaps_t = [], [], []
    render_seconds = 0.0
    status = 0
    frame = start_frame - 1
    try:
        if earlier:     # (interrupted here, the next --resume starts from `earlier` again)
            checkpoint.copy_video_prefix(earlier, video, start_frame)
        for frame in range(start_frame, frames):
            sim.advance_to(frame / fps)
            st = sim.state()
            diag.write(frame, st, sim.stats)
            if args.npz:
                snaps_x.append(st.x.astype(np.float32))
                snaps_v.append(st.v.astype(np.float32))
                snaps_t.append(st.time)
            if video is not None:
                t0 = time.perf_counter()
                video.write(renderer.frame(st))
                render_seconds += time.perf_counter() - t0
            if args.checkpoint_every and (frame + 1) % args.checkpoint_every == 0:
                checkpoint.save(ckpt_path, sim, scene, frame, fps)
            progress.update(frame, sim, final=frame == frames - 1)
    except KeyboardInterrupt:
        status = EXIT_INTERRUPTED
        print(f"\ninterrupted at frame {frame} (t = {sim.time:.4g} s)"
              + (f"; continue with --resume {ckpt_path}" if args.checkpoint_every else ""),
              file=sys.stderr)
    except Exception as exc:   # keep what was written, then re-raise after closing
        status = 1
        print(f"\nerror at frame {frame}: {exc!r}", file=sys.stderr)
        raise
    finally:
        try:
            # held: a Ctrl-C while closing waits for the files (a second one aborts)
            with hold_interrupts():
                if video is not None:
                    video.close()
                diag.close()
                if args.npz and snaps_x:
                    np.savez_compressed(npz_path, x=np.stack(snaps_x), v=np.stack(snaps_v),
                                        time=np.array(snaps_t), radius=scene.radius,
                                        mass=scene.mass)
                if renderer is not None:
                    renderer.close()
                written = [p for p, on in ((video_path, video is not None), (csv_path, True),
                                           (npz_path, args.npz and bool(snaps_x)),
                                           (ckpt_path, bool(args.checkpoint_every))) if on]
                print(f"wrote {', '.join(written)} ({diag.rows} frames)", file=sys.stderr)
        except KeyboardInterrupt:
            status = EXIT_INTERRUPTED

    st = sim.stats
    print(f"simulation: {sim.sim_seconds:.2f} s wall for {sim.time:g} s simulated, "
          f"{st['steps']} steps, {st['pair_collisions']} pair + {st['wall_collisions']} wall "
          f"collisions, max overlap {st['max_overlap']:.2e}, unresolved {st['unresolved']}; "
          f"rendering: {render_seconds:.2f} s", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
