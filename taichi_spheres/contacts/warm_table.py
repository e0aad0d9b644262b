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

    def warm_rows(self, n: int) -> dict:
        """The warm-start table of the first n spheres (numpy copies) and h_prev [s]."""
        out = dict(key=self.warm_key.to_numpy()[:n], lam=self.warm_lam.to_numpy()[:n],
                   kept=self.warm_n.to_numpy()[:n], loaded=self.state.loaded.to_numpy()[:n],
                   h_prev=float(self.h_prev[None]))
        if self.rules.substeps:
            out["near"] = self.state.near.to_numpy()[:n]
        for name in ("warm_t", "warm_r"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name).to_numpy()[:n]
        return out

    def load_warm(self, warm: dict) -> None:
        """Load a table written by :meth:`warm_rows` (same precision and slots)."""
        n = len(warm["kept"])
        key = self.warm_key.to_numpy()
        lam = self.warm_lam.to_numpy()
        kept = self.warm_n.to_numpy()
        loaded = self.state.loaded.to_numpy()
        key[:n], lam[:n], kept[:n] = warm["key"], warm["lam"], warm["kept"]
        loaded[:n] = warm["loaded"]
        self.state.loaded.from_numpy(loaded)
        if self.rules.substeps:      # (a table without: every sphere counts as near)
            near = self.state.near.to_numpy()
            near[:n] = warm["near"] if "near" in warm else 1
            self.state.near.from_numpy(near)
        self.warm_key.from_numpy(key)
        self.warm_lam.from_numpy(lam)
        self.warm_n.from_numpy(kept)
        self.h_prev[None] = warm["h_prev"]
        for name in ("warm_t", "warm_r"):
            field = getattr(self, name)
            if field is not None and name in warm:
                table = field.to_numpy()
                table[:n] = warm[name]
                field.from_numpy(table)

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
