"""Scalar parameters and counters shared by the step kernels (0-d / tiny fields).

Keeping scalars in fields (not baked-in constants, not kernel arguments) lets one
compiled kernel serve every step length and works on backends without f64
arguments (Metal).
"""

import numpy as np
import taichi as ti

# indices into StepParams.count (i32, per step)
REMAINING, PAIRS, WALLS, WALL_RESTS, MULTI, RESTED, SUPPORTED, FLOOR = range(8)
N_COUNTS = 8
# indices into StepParams.vals (real, per step)
SEP_OVERLAP, OPEN_OVERLAP, VMAX2, MOVED, E_PAIRS, E_WALLS, E_REST, VIRIAL = range(8)
N_VALS = 8


@ti.data_oriented
class StepParams:
    """h [s]; gravity [m/s^2]; box lo/hi/size [m]; restitution e, e_wall; counters.

    rest_speed [m/s]: pair approach speed below which e = 0 (0: rule off).
    up: unit vector against gravity (zero without gravity).
    count: (N_COUNTS,) i32 — remaining approaching overlaps, pair and wall
        collisions, wall rest clamps, spheres with more than one collision, pair
        collisions made perfectly inelastic by the rest rule, of which against a
        supported sphere, spheres supported by the floor, in the current step.
    vals: (N_VALS,) real — max relative overlap of separating pairs, of
        approaching pairs in the last detection, max |v|^2, max distance moved;
        kinetic energy removed by pair restitution, by wall restitution, by the
        rest rule [J]; collisional virial sum r_ij . dp_i [J s] (all in this step).
    """

    def __init__(self, scene, real, rest_speed=0.0):
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
        self.count = ti.field(ti.i32, shape=N_COUNTS)
        self.vals = ti.field(real, shape=N_VALS)
        self.gravity[None] = scene.gravity.tolist()
        self.lo[None] = scene.box_lo.tolist()
        self.hi[None] = scene.box_hi.tolist()
        self.size[None] = (scene.box_hi - scene.box_lo).tolist()
        self.e[None] = scene.restitution
        self.e_wall[None] = scene.wall_restitution
        self.rest_speed[None] = rest_speed
        g = float(np.linalg.norm(scene.gravity))
        self.up[None] = (-scene.gravity / g).tolist() if g > 0 else [0.0, 0.0, 0.0]

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
