"""Render (output stage): offscreen GGUI frames of a State snapshot.

The renderer never sees the simulation, only numpy snapshots (``State``), which it
uploads into its own float32 fields. GGUI needs Vulkan: on a machine without a GPU,
Debian's ``mesa-vulkan-drivers`` (lavapipe) provides it on the CPU.
"""
from __future__ import annotations

import os

import numpy as np
import taichi as ti

__all__ = ["Renderer", "RenderUnavailable", "palette", "VULKAN_HINT"]

VULKAN_HINT = ("offscreen rendering needs Vulkan; on Debian/Ubuntu install it with "
               "'sudo apt-get install mesa-vulkan-drivers libvulkan1' (lavapipe renders on "
               "the CPU), or run with --no-video for diagnostics only")

_PALETTE = np.array([
    [0.90, 0.30, 0.25], [0.25, 0.55, 0.90], [0.35, 0.75, 0.35], [0.95, 0.70, 0.20],
    [0.65, 0.40, 0.85], [0.20, 0.75, 0.75], [0.90, 0.50, 0.70], [0.60, 0.60, 0.60]],
    dtype=np.float32)


class RenderUnavailable(RuntimeError):
    """GGUI could not start (no Vulkan)."""


def palette(groups: np.ndarray) -> np.ndarray:
    """(N,) int group ids -> (N, 3) float32 RGB in [0, 1]."""
    return _PALETTE[np.asarray(groups) % len(_PALETTE)]


def speed_colours(v: np.ndarray, vmax: float) -> np.ndarray:
    """Blue (still) to red (>= vmax) by speed, (N, 3) float32."""
    t = np.clip(np.linalg.norm(v, axis=1) / max(vmax, 1e-300), 0.0, 1.0)[:, None]
    cold = np.array([0.20, 0.35, 0.85], dtype=np.float32)
    hot = np.array([0.95, 0.25, 0.15], dtype=np.float32)
    return ((1 - t) * cold + t * hot).astype(np.float32)


def spin_colours(omega: np.ndarray, radius: np.ndarray, vmax: float) -> np.ndarray:
    """Blue (no spin) to red (surface speed |omega| r >= vmax), (N, 3) float32."""
    return speed_colours(np.asarray(omega) * np.asarray(radius)[:, None], vmax)


def rgba(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) RGB in [0, 1] -> (N, 4) float32 RGBA, opaque."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return np.ascontiguousarray(np.concatenate([rgb, np.ones((len(rgb), 1), np.float32)], axis=1))


class Renderer:
    """Offscreen GGUI renderer for one scene.

    size: (width, height) in pixels, both divisible by 16 (H.264 macro blocks).
    camera: dict with optional 'position', 'lookat' (3 numbers, m) and 'fov' (deg);
    default: looking at the box centre from the front (-y), slightly above.
    colours: 'group' (``colour_table``, (N, 3) RGB in [0, 1], default one colour),
    'speed' (blue to red) or 'spin' (by surface speed |omega| r, blue to red).
    Spheres a sink took out (fewer rows in a State than in the scene) are not drawn;
    ``frame(state, ids)`` keeps the colours of the remaining ones (ids: their indices
    in the scene, Simulation.sphere_ids).
    """

    def __init__(self, scene, size=(640, 480), camera=None, colours="group", colour_table=None,
                 background=(0.08, 0.08, 0.10)):
        width, height = int(size[0]), int(size[1])
        if width % 16 or height % 16 or width <= 0 or height <= 0:
            raise ValueError(f"size {width}x{height}: width and height must be positive "
                             f"multiples of 16")
        if colours not in ("group", "speed", "spin"):
            raise ValueError(f"colours must be 'group', 'speed' or 'spin', got {colours!r}")
        self.size = (width, height)
        self.scene = scene
        self.colours = colours
        self.background = tuple(float(c) for c in background)
        # GGUI's imgui writes imgui.ini into the working directory: remove ours on close
        self._ini_existed = os.path.exists("imgui.ini")
        try:
            self.window = ti.ui.Window("taichi_spheres", self.size, show_window=False,
                                       vsync=False)
        except Exception as exc:   # GGUI raises RuntimeError (or worse) without Vulkan
            raise RenderUnavailable(f"{exc}. {VULKAN_HINT}") from exc
        self.canvas = self.window.get_canvas()
        self.gscene = self.window.get_scene()
        self.camera = ti.ui.Camera()
        n = scene.n
        self.pos = ti.Vector.field(3, ti.f32, shape=n)
        self.rad = ti.field(ti.f32, shape=n)
        # RGBA: GGUI's staging copy fills a missing alpha with a literal 1.0, which is an
        # f64 assigned into its f32 buffer when Taichi's default float is f64
        self.col = ti.Vector.field(4, ti.f32, shape=n)
        self.rad.from_numpy(scene.radius.astype(np.float32))
        table = palette(np.zeros(n, dtype=np.int64)) if colour_table is None else colour_table
        self.table = np.asarray(table, dtype=np.float32)
        self.col.from_numpy(rgba(self.table))
        self._drawn = n
        self.edges = ti.Vector.field(3, ti.f32, shape=24)
        self.edges.from_numpy(_box_edges(scene.box_lo, scene.box_hi))
        lo, hi = scene.box_lo, scene.box_hi
        centre = 0.5 * (lo + hi)
        extent = float(np.max(hi - lo))
        cam = dict(camera or {})
        position = cam.get("position", (centre[0], lo[1] - 1.6 * extent, centre[2] + 0.6 * extent))
        lookat = cam.get("lookat", tuple(centre))
        self.camera.position(*map(float, position))
        self.camera.lookat(*map(float, lookat))
        self.camera.up(0.0, 0.0, 1.0)
        self.camera.fov(float(cam.get("fov", 45.0)))
        self.light = (centre[0] - extent, lo[1] - 2.0 * extent, hi[2] + 2.0 * extent)
        self._vmax = None

    def frame(self, state, ids=None) -> np.ndarray:
        """Render a State (ids: the scene indices of its spheres, None: all of them);
        returns an (height, width, 3) uint8 RGB image, row 0 at the top."""
        self._load(state, ids)
        self._draw_colours(state)
        self.canvas.set_background_color(self.background)
        self.gscene.set_camera(self.camera)
        self.gscene.ambient_light((0.35, 0.35, 0.35))
        self.gscene.point_light(pos=tuple(map(float, self.light)), color=(0.9, 0.9, 0.9))
        self.gscene.particles(self.pos, radius=float(self.scene.radius.max()),
                              per_vertex_color=self.col, per_vertex_radius=self.rad)
        self.gscene.lines(self.edges, width=2.0, color=(0.75, 0.75, 0.75))
        self.canvas.scene(self.gscene)
        img = self.window.get_image_buffer_as_numpy()     # (width, height, 4), origin bottom-left
        rgb = np.ascontiguousarray(np.flipud(np.transpose(img[:, :, :3], (1, 0, 2))))
        return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

    def _load(self, state, ids):
        """Positions of the State's spheres; the others (discharged) get radius 0."""
        n, m = self.scene.n, len(state.x)
        pos = np.zeros((n, 3), dtype=np.float32)
        pos[:m] = state.x
        self.pos.from_numpy(pos)
        if m != self._drawn:
            ids = np.arange(m) if ids is None else np.asarray(ids)
            rad = np.zeros(n, dtype=np.float32)
            rad[:m] = self.scene.radius[ids]
            self.rad.from_numpy(rad)
            col = np.zeros((n, 3), dtype=np.float32)
            col[:m] = self.table[ids]
            self.col.from_numpy(rgba(col))
            self._drawn = m

    def _draw_colours(self, state):
        """Speed or spin colours of this frame (scale fixed by the first frame)."""
        if self.colours == "group":
            return
        if self.colours == "speed":
            value = np.linalg.norm(state.v, axis=1)
            rgb = speed_colours
            args = (state.v,)
        else:
            value = np.linalg.norm(state.omega, axis=1) * state.radius
            rgb = spin_colours
            args = (state.omega, state.radius)
        if self._vmax is None:   # fixed scale from the first frame: colours comparable
            self._vmax = float(value.max()) if len(value) else 1.0
            self._vmax = self._vmax or 1.0
        col = np.zeros((self.scene.n, 3), dtype=np.float32)
        col[:len(value)] = rgb(*args, self._vmax)
        self.col.from_numpy(rgba(col))

    def close(self):
        try:
            self.window.destroy()
        except Exception:   # already gone with the Taichi runtime
            pass
        if not self._ini_existed and os.path.exists("imgui.ini"):
            os.remove("imgui.ini")


def _box_edges(lo, hi) -> np.ndarray:
    """The 12 edges of the box as 24 line end points, (24, 3) float32."""
    corners = np.array([[lo[0] if i & 1 == 0 else hi[0], lo[1] if i & 2 == 0 else hi[1],
                         lo[2] if i & 4 == 0 else hi[2]] for i in range(8)], dtype=np.float32)
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
    return np.array([corners[k] for ab in pairs for k in ab], dtype=np.float32)
