"""Output stage: mp4 encoding (imageio + ffmpeg, H.264 yuv420p) and the diagnostics CSV."""
from __future__ import annotations

import csv
import os

import numpy as np

from . import observe
from .interrupts import hold_interrupts

__all__ = ["VideoWriter", "DiagnosticsWriter", "CSV_COLUMNS", "check_writable"]

CSV_COLUMNS = ["frame", "time", "kinetic", "potential", "total", "px", "py", "pz",
               "steps", "pair_collisions", "wall_collisions", "wall_rests", "sweeps",
               "max_overlap", "unresolved", "dt", "sweep_limit_hits",
               "multi_collision_spheres", "collapse_collisions", "energy_pair_restitution",
               "energy_wall_restitution", "energy_collapse", "energy_contacts",
               "projected_pairs", "contacts", "contact_iterations", "discharged",
               "discharged_mass", "energy_discharged", "rotational"]
#: CSV columns copied from Simulation.stats as they are
_STATS_COLUMNS = CSV_COLUMNS[8:-1]


def check_writable(path: str) -> None:
    """Fail before simulating if ``path`` cannot be created (ValueError naming it)."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if not os.path.isdir(folder):
        raise ValueError(f"output folder does not exist: {folder} (create it first)")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"output folder is not writable: {folder}")
    if os.path.isdir(path):
        raise ValueError(f"output path is a directory: {path}")


class VideoWriter:
    """Append RGB frames (H, W, 3) uint8 to an mp4; always closes into a playable file."""

    def __init__(self, path: str, fps: float, quality: int = 8):
        import imageio.v2 as imageio   # output stage only: the engine never needs it
        self.path = path
        self.frames = 0
        self._writer = imageio.get_writer(path, fps=fps, codec="libx264", quality=quality,
                                          pixelformat="yuv420p", macro_block_size=16,
                                          ffmpeg_log_level="error")

    def write(self, rgb: np.ndarray) -> None:
        with hold_interrupts():
            self._writer.append_data(rgb)
            self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            with hold_interrupts():
                self._writer.close()
                self._writer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class DiagnosticsWriter:
    """One CSV row per frame: energies [J], momentum [kg m/s], cumulative counters."""

    def __init__(self, path: str, gravity, keep_frames: int = 0):
        """keep_frames > 0 (resuming): keep the first keep_frames rows of an existing file,
        each value under its own column (nan in a column the file lacks: a CSV written
        before the column existed)."""
        self.path = path
        self.gravity = np.asarray(gravity, dtype=np.float64)
        kept = []
        if keep_frames and os.path.exists(path):
            with open(path, newline="") as fh:
                rows = list(csv.DictReader(fh))[:keep_frames]
            kept = [[row.get(c, "nan") for c in CSV_COLUMNS] for row in rows]
        self._fh = open(path, "w", newline="")
        self._csv = csv.writer(self._fh)
        self._csv.writerow(CSV_COLUMNS)
        self._csv.writerows(kept)
        self.rows = len(kept)

    def write(self, frame: int, state, stats: dict) -> dict:
        ke = observe.kinetic_energy(state)
        rot = observe.rotational_energy(state)
        pe = observe.potential_energy(state, self.gravity)
        p = observe.momentum(state)
        row = dict(frame=frame, time=state.time, kinetic=ke, potential=pe,
                   total=ke + rot + pe, px=p[0], py=p[1], pz=p[2], rotational=rot)
        row.update({c: stats[c] for c in _STATS_COLUMNS})
        with hold_interrupts():
            self._csv.writerow([_fmt(row[c]) for c in CSV_COLUMNS])
            self._fh.flush()
            self.rows += 1
        return row

    def close(self):
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _fmt(value):
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, np.integer):
        return int(value)
    return value
