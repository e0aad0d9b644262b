"""Scalar parameters and counters shared by the step kernels (0-d / tiny fields).

Keeping scalars in fields (not baked-in constants, not kernel arguments) lets one
compiled kernel serve every step length and works on backends without f64
arguments (Metal).
"""

import numpy as np
import taichi as ti
from taichi.lang import impl

# indices into StepParams.count (i32, per step)
(REMAINING, PAIRS, WALLS, WALL_RESTS, MULTI, RESTED, SUPPORTED, FLOOR, PROJECTED,
 PROJECTED_PAIRS, WALL_RESTED) = range(11)
N_COUNTS = 11
# indices into StepParams.vals (real, per step)
SEP_OVERLAP, OPEN_OVERLAP, VMAX2, MOVED, E_PAIRS, E_WALLS, E_REST, VIRIAL, PROJ_WORST = range(9)
N_VALS = 9


class Slots:
    """``n`` scalar (0-d) fields of one dtype, addressed as ``slots[k]`` (k a Python int):
    read and written in kernels, read in Python. Separate 0-d fields rather than one (n,) field: Taichi
    reduces atomics on a 0-d field thread-locally (one atomic per thread and loop),
    while atomics on elements of one small 1-d field contend between threads (about
    5x slower on this project's 2-core VM: ``python tools/launch_overhead.py``)."""

    def __init__(self, dtype, n):
        self.fields = [ti.field(dtype, shape=()) for _ in range(n)]

    def __getitem__(self, k):
        if impl.inside_kernel():
            return impl.subscript(None, self.fields[k], None)
        return self.fields[k][None]


@ti.data_oriented
class StepParams:
    """h [s]; gravity [m/s^2]; box lo/hi/size [m]; restitution e, e_wall; counters.

    rest_speed [m/s]: pair approach speed below which e = 0 (0: rule off).
    up: unit vector against gravity (zero without gravity).
    count: N_COUNTS i32 slots (:class:`Slots`) — remaining approaching overlaps, pair and wall
        collisions, wall rest clamps, spheres with more than one collision, pair
        collisions made perfectly inelastic by the rest rule, of which against a
        supported sphere, spheres supported by the floor, in the current step; of a
        fused step (fused.py) also: 1 if it ran the overlap projection, and the pairs
        the projection pushed; wall impacts made perfectly inelastic by the rest
        rule (floor-like walls only).
    vals: N_VALS real slots — max relative overlap of separating pairs, of
        approaching pairs in the last detection, max |v|^2, max distance moved;
        kinetic energy removed by pair restitution, by wall restitution, by the
        rest rule [J]; collisional virial sum r_ij . dp_i [J s] (all in this step);
        of a fused step that projected: the largest relative overlap its last
        projection iteration measured.
    """

    def __init__(self, real):
        self.real = real
        self.rest_speed = ti.field(real, shape=())
        self.up = ti.Vector.field(3, real, shape=())
        self.h = ti.field(real, shape=())
        self.gravity = ti.Vector.field(3, real, shape=())
        self.lo = ti.Vector.field(3, real, shape=())
        self.hi = ti.Vector.field(3, real, shape=())
        self.size = ti.Vector.field(3, real, shape=())
        self.e = ti.field(real, shape=())
        self.e_wall = ti.field(real, shape=())
        self.count = Slots(ti.i32, N_COUNTS)
        self.vals = Slots(real, N_VALS)
        # host copies the step reads back in one launch (to_numpy costs ~0.3 ms per
        # field on the CPU backend, a kernel with array arguments ~0.08 ms:
        # tools/launch_overhead.py)
        self.count_host = np.zeros(N_COUNTS, dtype=np.int32)
        self.vals_host = np.zeros(N_VALS, dtype=np.float64 if real == ti.f64 else np.float32)

        @ti.kernel
        def copy_out(counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                     vals: ti.types.ndarray(dtype=real, ndim=1)):
            for k in ti.static(range(N_COUNTS)):
                counts[k] = self.count[k]
            for k in ti.static(range(N_VALS)):
                vals[k] = self.vals[k]

        self._copy_out = copy_out

    def bind(self, scene, rest_speed=0.0):
        """Load a scene's gravity, box, restitutions and the rest speed [m/s]."""
        self.gravity[None] = scene.gravity.tolist()
        self.lo[None] = scene.box_lo.tolist()
        self.hi[None] = scene.box_hi.tolist()
        self.size[None] = (scene.box_hi - scene.box_lo).tolist()
        self.e[None] = scene.restitution
        self.e_wall[None] = scene.wall_restitution
        self.rest_speed[None] = rest_speed
        g = float(np.linalg.norm(scene.gravity))
        self.up[None] = (-scene.gravity / g).tolist() if g > 0 else [0.0, 0.0, 0.0]

    def read_back(self):
        """(count, vals) of this step as numpy arrays (count_host and vals_host, reused:
        copy them to keep them past the next call)."""
        self._copy_out(self.count_host, self.vals_host)
        return self.count_host, self.vals_host

    @ti.func
    def reset_step(self):
        """Zero the per-step counters (call at kernel top level)."""
        for k in ti.static(range(N_COUNTS)):
            self.count[k] = 0
        for k in ti.static(range(N_VALS)):
            self.vals[k] = 0

    @ti.func
    def reset_detection(self):
        """Zero what one detection pass measures (call at kernel top level)."""
        self.count[REMAINING] = 0
        self.vals[OPEN_OVERLAP] = 0
