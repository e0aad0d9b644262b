"""The contact solver's warm-start table between steps and between engines
(contacts/solver.py, mixed into ContactSolver).

Each sphere a keeps the rows it owned in the last step (``warm_key[a, t]``: the partner
b, or -1 - wall; ``warm_lam``, ``warm_t``, ``warm_r``: their impulses; ``warm_n[a]``: how
many, more than ``warm_slots`` meaning none kept), with ``state.loaded`` and
``state.near``. A Simulation parked off its engine takes the table to the host
(``warm_rows``) and back (``load_warm``). When a sink takes spheres out
(discharge.py), ``keep_spheres`` moves the table of the spheres that stay down to
their new indices in the fields, renumbering their partners, as the host's
``discharge.renumber_warm`` does to a parked table: the same bits without the round
trip.
"""

import numpy as np
import taichi as ti

from ..discharge import DROPPED_PARTNER
from ..state import has_field

__all__ = ["WarmTable", "copy_warm_row", "WARM_FIELDS"]

#: a sphere's warm-start rows in the solver's fields (warm_t with friction, warm_r with
#: rolling friction, else None), as copy_warm_row moves them
WARM_FIELDS = ("warm_key", "warm_lam", "warm_t", "warm_r", "warm_n")


@ti.func
def copy_warm_row(src: ti.template(), src_flags: ti.template(), i, dst: ti.template(),
                  dst_flags: ti.template(), j, new_index: ti.template(), n_old):
    """Row i of ``src``'s warm-start table (warm_key, warm_lam, warm_t, warm_r, warm_n;
    a ContactSolver or takeout.StayerScratch) and the loaded and near flags of
    ``src_flags`` (its SphereState, or the scratch) to row j of ``dst`` and
    ``dst_flags``; the partners b in [0, n_old) of the rows in use renumbered to
    new_index[b] (DROPPED_PARTNER where new_index[b] < 0; n_old = 0: none)."""
    used = src.warm_n[i]
    for t in ti.static(range(src.warm_key.shape[1])):
        key = src.warm_key[i, t]
        if t < used and key >= 0 and key < n_old:
            key = ti.select(new_index[key] >= 0, new_index[key], DROPPED_PARTNER)
        dst.warm_key[j, t] = key
        dst.warm_lam[j, t] = src.warm_lam[i, t]
        if ti.static(has_field(src, "warm_t")):
            dst.warm_t[j, t] = src.warm_t[i, t]
        if ti.static(has_field(src, "warm_r")):
            dst.warm_r[j, t] = src.warm_r[i, t]
    dst.warm_n[j] = used
    dst_flags.loaded[j] = src_flags.loaded[i]
    dst_flags.near[j] = src_flags.near[i]


@ti.data_oriented
class WarmTable:
    """warm_rows, load_warm and keep_spheres over ContactSolver's fields (module
    docstring)."""

    def _warm_arrays(self, n: int) -> dict:
        """Host arrays for the table of n spheres in the fields' types: key, lam, kept,
        flags (loaded, near), h (h_prev), and t and r (warm_t, warm_r; a (1, 1, 3)
        placeholder where the solver has no such field)."""
        real = np.float64 if self.real == ti.f64 else np.float32
        slots = self.warm_key.shape[1]
        arrays = dict(key=np.zeros((n, slots), np.int32), lam=np.zeros((n, slots), real),
                      kept=np.zeros(n, np.int32), flags=np.zeros((n, 2), np.int32),
                      h=np.zeros(1, real))
        for name in ("t", "r"):
            held = getattr(self, "warm_" + name) is not None
            arrays[name] = np.zeros((n, slots, 3) if held else (1, 1, 3), real)
        return arrays

    def warm_rows(self, n: int) -> dict:
        """The warm-start table of the first n spheres (numpy copies) and h_prev [s]
        (one launch)."""
        arrays = self._warm_arrays(n)
        self._read_warm(n, *(arrays[k] for k in ("key", "lam", "kept", "flags", "h", "t", "r")))
        out = dict(key=arrays["key"], lam=arrays["lam"], kept=arrays["kept"],
                   loaded=arrays["flags"][:, 0].copy(), h_prev=float(arrays["h"][0]))
        if self.rules.substeps:
            out["near"] = arrays["flags"][:, 1].copy()
        for name in ("t", "r"):
            if getattr(self, "warm_" + name) is not None:
                out["warm_" + name] = arrays[name]
        return out

    def load_warm(self, warm: dict) -> None:
        """Load a table written by :meth:`warm_rows` (same precision and slots) into the
        first rows (one launch; a table without "near" marks every sphere near, one
        without warm_t or warm_r leaves those fields as they are)."""
        n = len(warm["kept"])
        arrays = self._warm_arrays(n)
        arrays["key"][:], arrays["lam"][:], arrays["kept"][:] = (warm["key"], warm["lam"],
                                                                 warm["kept"])
        arrays["flags"][:, 0] = warm["loaded"]
        arrays["flags"][:, 1] = warm["near"] if "near" in warm else 1
        arrays["h"][0] = warm["h_prev"]
        loads = {}
        for name in ("t", "r"):
            loads[name] = int(getattr(self, "warm_" + name) is not None
                              and "warm_" + name in warm)
            if loads[name]:
                arrays[name][:] = warm["warm_" + name]
        self._write_warm(n, *(arrays[k] for k in ("key", "lam", "kept", "flags", "h", "t", "r")),
                         loads["t"], loads["r"])

    @ti.kernel
    def _read_warm(self, n: ti.i32, key: ti.types.ndarray(dtype=ti.i32, ndim=2),
                   lam: ti.types.ndarray(ndim=2), kept: ti.types.ndarray(dtype=ti.i32, ndim=1),
                   flags: ti.types.ndarray(dtype=ti.i32, ndim=2), h: ti.types.ndarray(ndim=1),
                   t: ti.types.ndarray(ndim=3), r: ti.types.ndarray(ndim=3)):
        """The table's first n rows into the arrays (_warm_arrays)."""
        for i in range(n):
            kept[i] = self.warm_n[i]
            flags[i, 0] = self.state.loaded[i]
            flags[i, 1] = self.state.near[i]
            for s in range(self.warm_key.shape[1]):
                key[i, s] = self.warm_key[i, s]
                lam[i, s] = self.warm_lam[i, s]
                for c in ti.static(range(3)):
                    if ti.static(has_field(self, "warm_t")):
                        t[i, s, c] = self.warm_t[i, s][c]
                    if ti.static(has_field(self, "warm_r")):
                        r[i, s, c] = self.warm_r[i, s][c]
        h[0] = self.h_prev[None]

    @ti.kernel
    def _write_warm(self, n: ti.i32, key: ti.types.ndarray(dtype=ti.i32, ndim=2),
                    lam: ti.types.ndarray(ndim=2), kept: ti.types.ndarray(dtype=ti.i32, ndim=1),
                    flags: ti.types.ndarray(dtype=ti.i32, ndim=2), h: ti.types.ndarray(ndim=1),
                    t: ti.types.ndarray(ndim=3), r: ti.types.ndarray(ndim=3), has_t: ti.i32,
                    has_r: ti.i32):
        """The arrays (_warm_arrays) into the table's first n rows (near only with
        substeps; warm_t, warm_r where has_t, has_r)."""
        for i in range(n):
            self.warm_n[i] = kept[i]
            self.state.loaded[i] = flags[i, 0]
            if ti.static(self.rules.substeps):
                self.state.near[i] = flags[i, 1]
            for s in range(self.warm_key.shape[1]):
                self.warm_key[i, s] = key[i, s]
                self.warm_lam[i, s] = lam[i, s]
                for c in ti.static(range(3)):
                    if ti.static(has_field(self, "warm_t")):
                        if has_t:
                            self.warm_t[i, s][c] = t[i, s, c]
                    if ti.static(has_field(self, "warm_r")):
                        if has_r:
                            self.warm_r[i, s][c] = r[i, s, c]
        self.h_prev[None] = h[0]

    def keep_spheres(self, scene, geom, reach, kept) -> None:
        """After a sink took spheres out of the bound scene: ``scene`` holds the spheres
        that stay, ``kept`` ((n_before,) bool, or None: all stayed) says which. Moves
        their warm-start table, loaded and near flags to their new indices (partners
        renumbered; rows whose partner left keep DROPPED_PARTNER), clears them beyond,
        and loads the scene's scalars as bind does (h_prev stays). The same fields as
        bind followed by load_warm of discharge.renumber_warm's table."""
        self.bind_scalars(scene, geom, reach)
        if kept is None:
            return
        kept = np.asarray(kept, dtype=bool)
        new_index = np.where(kept, np.cumsum(kept) - 1, -1).astype(np.int32)
        self._move_warm_rows(new_index, int(scene.n))

    @ti.kernel
    def _move_warm_rows(self, new_index: ti.types.ndarray(dtype=ti.i32, ndim=1), n_new: ti.i32):
        """Row i of the table to row new_index[i] >= 0 in increasing i (new_index[i] <=
        i: no row is overwritten before it is read), partners b >= 0 in the rows in use
        renumbered; rows n_new.. of the old count emptied."""
        n_old = new_index.shape[0]
        ti.loop_config(serialize=True)
        for i in range(n_old):
            j = new_index[i]
            if j >= 0:
                self.move_warm_row(i, j, new_index, n_old)
        for i in range(n_new, n_old):
            self.empty_warm_row(i)

    @ti.func
    def move_warm_row(self, i, j, new_index: ti.template(), n_old):
        """Sphere i's warm-start rows, loaded and near flags to row j <= i, the partners
        b in [0, n_old) of its rows in use renumbered to new_index[b] (DROPPED_PARTNER
        where new_index[b] < 0). ``new_index``: (n_old,) i32, a field or an ndarray."""
        copy_warm_row(self, self.state, i, self, self.state, j, new_index, n_old)

    @ti.func
    def empty_warm_row(self, i):
        """Row i of the table (a sphere index no longer in use) holds no rows."""
        self.warm_n[i] = 0
        self.state.loaded[i] = 0
        self.state.near[i] = 0
