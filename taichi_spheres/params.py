"""Scalar parameters and counters shared by the step kernels (0-d fields).

Keeping scalars in fields (not baked-in constants, not kernel arguments) lets one
compiled kernel serve every step length and works on backends without f64
arguments (Metal). Each counter is a 0-d field of its own, named after what it
counts (COUNTS, VALUES): Taichi reduces atomics on a 0-d field thread-locally (one
atomic per thread and loop), while atomics on elements of one small 1-d field contend
between threads (about 5x slower on 2 cores: ``python tools/launch_overhead.py``).
"""

import types

import numpy as np
import taichi as ti

from .materials import MAX_MATERIALS

#: static geometry objects a scene may have (planes, cylinders, cones: geometry.py)
MAX_GEOMETRY = 16
#: numbers per geometry object (geometry.PACKED_WIDTH: kind, point, axis, r0, r1,
#: length, inside, hole, restitution, friction)
GEOMETRY_WIDTH = 14
#: sinks a scene may have (geometry.Sink: regions that discharge spheres)
MAX_SINKS = 8

#: i32 counters of one step: approaching overlaps left by the last detection; pair and
#: wall collisions (impacts); wall rest clamps (spheres put on a wall); spheres with
#: more than one collision; pair collisions made perfectly inelastic by the collapse
#: rule; of a fused step (fused.py) also: 1 if it ran the overlap projection, and the
#: pairs the projection pushed; of the contact solver (contacts/solver.py): its rows,
#: velocity sweeps and position sweeps; spheres whose centre is in a sink at the end
#: of the drift (simulation.py removes them); 1 if the solver scaled its warm start
#: down (contacts/warm_energy.py); with Rules.substeps, collisions of spheres with a
#: row to a wall, an object or a loaded sphere at the last solve (state.near;
#: stepping.py ends the step at them).
COUNTS = ("remaining", "pair_collisions", "wall_collisions", "wall_rests",
          "multi_collision_spheres", "collapse_collisions", "projected", "projected_pairs",
          "contacts", "contact_iterations", "position_iterations", "in_sinks",
          "warm_starts_scaled", "near_hits")
#: real values of one step: max relative overlap of separating pairs, of approaching
#: pairs in the last detection; max |v|^2 [m^2/s^2]; max distance moved since the grid
#: was built [m]; energy removed by pair restitution, wall restitution, the collapse
#: rule and the contact solver [J]; collisional virial sum r_ij . dp_i [J s]; of a
#: fused step that projected: the largest relative overlap its last projection
#: iteration measured; of the contact solver: the residual of its last velocity sweep
#: [m/s], the largest relative overlap of its rows after the solve, and with
#: Rules.substeps max |v|^2 of the spheres its rows held (a row impulse > 0)
#: [m^2/s^2].
VALUES = ("sep_overlap", "open_overlap", "vmax2", "moved", "energy_pair_restitution",
          "energy_wall_restitution", "energy_collapse", "energy_contacts", "virial",
          "proj_worst", "contact_residual", "contact_overlap", "vmax2_near")
#: counters a step run in substeps (Rules.substeps) takes from its last substep (and
#: the solve after it), and those it takes the largest of; the others add up
#: (an approaching overlap a substep left is found again by the next one: "remaining"
#: and "open_overlap" are the last substep's)
LAST_OF_SUBSTEPS = ("remaining", "open_overlap", "in_sinks", "vmax2", "moved",
                    "contact_residual", "contact_overlap", "vmax2_near")
LARGEST_OF_SUBSTEPS = ("sep_overlap", "proj_worst")
#: the fields StepParams.bind loads from a scene (all but h and the counters), and
#: with materials the pair tables
BOUND = ("gravity", "lo", "hi", "size", "e_wall", "rest_speed", "mu_wall", "beta_max",
         "e", "mu", "mu_roll", "geo", "n_geo", "sink_lo", "sink_hi", "n_sinks")
PAIR_TABLES = ("pair_e", "pair_mu", "pair_mu_roll")


def merge_substeps(before, last):
    """The counters of a step run in substeps: ``before``, those of its earlier
    substeps merged (None if there were none), and ``last``, read back after its last
    substep and the solve (namespaces of :meth:`StepParams.read_back`)."""
    if before is None:
        return last
    out = {}
    for name in COUNTS + VALUES:
        a, b = getattr(before, name), getattr(last, name)
        out[name] = b if name in LAST_OF_SUBSTEPS else (
            max(a, b) if name in LARGEST_OF_SUBSTEPS else a + b)
    return types.SimpleNamespace(**out)


@ti.data_oriented
class StepParams:
    """h [s]; gravity [m/s^2]; box lo/hi/size [m]; restitution e, e_wall; rest_speed
    [m/s]: the impact speed (simulation.rest_speed_for; 0: every approach is an
    impact); friction coefficients mu, mu_wall, mu_roll and beta_max (the sticking
    bound of the tangential restitution: contacts/friction.py); the geometry table
    geo (MAX_GEOMETRY, GEOMETRY_WIDTH) with n_geo objects (geometry.py's packed
    rows); sink_lo, sink_hi (MAX_SINKS,) vec3 with n_sinks regions [m]; with
    ``materials`` (state.Features.materials) the pair tables pair_e, pair_mu,
    pair_mu_roll (MAX_MATERIALS, MAX_MATERIALS) of materials.pair_table (else the
    scalars e, mu, mu_roll hold the one set of pair values); and the step's counters,
    one 0-d field per name of COUNTS (i32) and VALUES (real):
    ``params.pair_collisions[None]``."""

    def __init__(self, real, materials: bool = False):
        self.real = real
        self.materials = materials
        shape = (MAX_MATERIALS, MAX_MATERIALS)
        self.pair_e, self.pair_mu, self.pair_mu_roll = (
            (ti.field(real, shape=shape) for _ in range(3)) if materials else (None,) * 3)
        self.rest_speed = ti.field(real, shape=())
        self.h = ti.field(real, shape=())
        self.gravity = ti.Vector.field(3, real, shape=())
        self.lo = ti.Vector.field(3, real, shape=())
        self.hi = ti.Vector.field(3, real, shape=())
        self.size = ti.Vector.field(3, real, shape=())
        self.e = ti.field(real, shape=())
        self.e_wall = ti.field(real, shape=())
        self.mu = ti.field(real, shape=())
        self.mu_wall = ti.field(real, shape=())
        self.mu_roll = ti.field(real, shape=())
        self.beta_max = ti.field(real, shape=())
        self.geo = ti.field(real, shape=(MAX_GEOMETRY, GEOMETRY_WIDTH))
        self.n_geo = ti.field(ti.i32, shape=())
        self.sink_lo = ti.Vector.field(3, real, shape=MAX_SINKS)
        self.sink_hi = ti.Vector.field(3, real, shape=MAX_SINKS)
        self.n_sinks = ti.field(ti.i32, shape=())
        self.counters = [ti.field(ti.i32, shape=()) for _ in COUNTS]
        self.values = [ti.field(real, shape=()) for _ in VALUES]
        for name, field in zip(COUNTS + VALUES, self.counters + self.values):
            setattr(self, name, field)
        # host copies the step reads back in one launch (to_numpy costs ~0.3 ms per
        # field on the CPU backend, a kernel with array arguments ~0.08 ms:
        # tools/launch_overhead.py)
        self._count_host = np.zeros(len(COUNTS), dtype=np.int32)
        self._value_host = np.zeros(len(VALUES), dtype=np.float64 if real == ti.f64
                                    else np.float32)

        @ti.kernel
        def copy_out(counts: ti.types.ndarray(dtype=ti.i32, ndim=1),
                     values: ti.types.ndarray(dtype=real, ndim=1)):
            for k in ti.static(range(len(COUNTS))):
                counts[k] = self.counters[k][None]
            for k in ti.static(range(len(VALUES))):
                values[k] = self.values[k][None]

        self._copy_out = copy_out
        self.host_load = None      # the engine's hostload.FieldLoad

    def loaded_fields(self) -> tuple:
        """The fields bind loads (hostload.FieldLoad)."""
        return BOUND + (PAIR_TABLES if self.materials else ())

    def bind(self, scene, rest_speed=0.0):
        """Load a scene's gravity, box, restitutions, friction coefficients, geometry
        objects and sinks, and the rest speed [m/s] (one launch: hostload.py)."""
        beta0 = float(getattr(scene, "tangential_restitution", -1.0))
        values = dict(gravity=scene.gravity, lo=scene.box_lo, hi=scene.box_hi,
                      size=scene.box_hi - scene.box_lo, e_wall=scene.wall_restitution,
                      rest_speed=rest_speed,
                      mu_wall=float(getattr(scene, "wall_friction", 0.0)),
                      beta_max=0.0 if beta0 == -1.0 else beta0)
        values.update(self.material_values(scene))
        values.update(self.geometry_values(getattr(scene, "geometry", ())))
        values.update(self.sink_values(getattr(scene, "sinks", ())))
        self.host_load.write(self, **values)

    def material_values(self, scene) -> dict:
        """The pair values: the scalars e, mu, mu_roll from the material of sphere 0 (all
        pairs alike without Features.materials), and with it the tables of
        scene.pair_values()."""
        table = scene.pair_values()
        m0 = int(scene.material[0])
        out = dict(zip(("e", "mu", "mu_roll"), (float(c) for c in table[m0, m0])))
        if self.materials:
            full = np.zeros((MAX_MATERIALS, MAX_MATERIALS, 3))
            full[:len(table), :len(table)] = table
            out.update(zip(PAIR_TABLES, (full[..., c] for c in range(3))))
        return out

    @ti.func
    def restitution_of(self, a, b):
        """Pair restitution e of materials a, b."""
        out = self.e[None]
        if ti.static(self.materials):
            out = self.pair_e[a, b]
        return out

    @ti.func
    def friction_of(self, a, b):
        """Pair friction coefficient mu of materials a, b."""
        out = self.mu[None]
        if ti.static(self.materials):
            out = self.pair_mu[a, b]
        return out

    @ti.func
    def rolling_of(self, a, b):
        """Pair rolling friction mu_r of materials a, b (a, a on a wall)."""
        out = self.mu_roll[None]
        if ti.static(self.materials):
            out = self.pair_mu_roll[a, b]
        return out

    @staticmethod
    def sink_values(sinks) -> dict:
        """The scene's sink regions (low, high corners [m]) as bind loads them."""
        if len(sinks) > MAX_SINKS:
            raise ValueError(f"at most {MAX_SINKS} sinks, got {len(sinks)}")
        lo = np.zeros((MAX_SINKS, 3))
        hi = np.zeros((MAX_SINKS, 3))
        for k, sink in enumerate(sinks):
            lo[k], hi[k] = sink.low, sink.high
        return dict(sink_lo=lo, sink_hi=hi, n_sinks=len(sinks))

    @staticmethod
    def geometry_values(geometry) -> dict:
        """The packed rows of the scene's geometry objects (geometry.py) as bind loads
        them."""
        if len(geometry) > MAX_GEOMETRY:
            raise ValueError(f"at most {MAX_GEOMETRY} geometry objects, got {len(geometry)}")
        table = np.zeros((MAX_GEOMETRY, GEOMETRY_WIDTH), dtype=np.float64)
        for k, g in enumerate(geometry):
            table[k] = g.packed()
        return dict(geo=table, n_geo=len(geometry))

    @ti.func
    def in_a_sink(self, x) -> bool:
        """Whether the point x [m] is in a sink region [sink_lo, sink_hi) (as
        discharge.in_sinks compares on the host, in the fields' precision)."""
        inside = False
        for k in range(self.n_sinks[None]):
            if (x >= self.sink_lo[k]).all():
                if (x < self.sink_hi[k]).all():
                    inside = True
        return inside

    def read_back(self):
        """This step's counters as one namespace (attributes named as COUNTS and VALUES:
        ints and floats), read in one launch."""
        self._copy_out(self._count_host, self._value_host)
        out = dict(zip(COUNTS, self._count_host.tolist()))
        out.update(zip(VALUES, self._value_host.tolist()))
        return types.SimpleNamespace(**out)

    @ti.func
    def reset_step(self):
        """Zero the per-step counters (call at kernel top level)."""
        for k in ti.static(range(len(COUNTS))):
            self.counters[k][None] = 0
        for k in ti.static(range(len(VALUES))):
            self.values[k][None] = 0

    @ti.func
    def reset_detection(self):
        """Zero what one detection pass measures (call at kernel top level)."""
        self.remaining[None] = 0
        self.open_overlap[None] = 0
