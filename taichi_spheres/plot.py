"""PNG plots of a run's diagnostics CSV (``taichi-spheres plot run.csv``).

Three panels against simulated time [s]: the energies [J] (kinetic, potential, total,
and the cumulative losses to pair restitution, wall restitution, the collapse rule and
the contact solver, and the energy sinks took out);
pair and wall collisions per simulated second (from the cumulative counts, per frame
interval); the largest overlap left after a step so far, as a fraction of the contact
distance. Needs matplotlib (the ``plot`` extra), imported only here, with the Agg
backend (no display needed).
"""
from __future__ import annotations

import csv
import os

import numpy as np

__all__ = ["read_diagnostics", "collision_rate", "plot_diagnostics", "PlotUnavailable",
           "REQUIRED_COLUMNS"]

#: CSV columns the plots read (output.CSV_COLUMNS has them all)
REQUIRED_COLUMNS = ("time", "kinetic", "potential", "total", "pair_collisions",
                    "wall_collisions", "max_overlap", "energy_pair_restitution",
                    "energy_wall_restitution", "energy_collapse", "energy_contacts")
#: the energy losses drawn, by CSV column and legend label
LOSSES = (("energy_pair_restitution", "lost: pair restitution"),
          ("energy_wall_restitution", "lost: wall restitution"),
          ("energy_collapse", "lost: collapse rule"),
          ("energy_contacts", "lost: contacts"),
          ("energy_discharged", "taken out at sinks"))
#: columns read where the CSV has them (CSVs written before they existed lack them)
OPTIONAL_COLUMNS = ("energy_discharged",)
#: collision rates are averaged over at most this many intervals of equal frame count
RATE_POINTS = 200
#: figure size [inches] and resolution [dots per inch]
FIGSIZE, DPI = (7.0, 8.0), 90


class PlotUnavailable(RuntimeError):
    """matplotlib is not installed."""


def read_diagnostics(path: str) -> dict:
    """The REQUIRED_COLUMNS of a diagnostics CSV as float arrays, and the
    OPTIONAL_COLUMNS (zeros where the CSV lacks them); ValueError naming the
    file and what is wrong (missing, not a CSV of ``taichi-spheres run``, no rows, a
    value that is not a number)."""
    if not os.path.isfile(path):
        raise ValueError(f"no such file: {path}")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in REQUIRED_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path} lacks the column(s) {', '.join(missing)}: is it the "
                             f"diagnostics CSV that 'taichi-spheres run' writes?")
        rows = list(reader)
        present = [c for c in OPTIONAL_COLUMNS if c in (reader.fieldnames or [])]
    if not rows:
        raise ValueError(f"{path} has no rows (a run that wrote no frame)")
    data = {c: np.zeros(len(rows)) for c in OPTIONAL_COLUMNS}
    for column in REQUIRED_COLUMNS + tuple(present):
        try:
            data[column] = np.array([float(row[column]) for row in rows])
        except (TypeError, ValueError):
            raise ValueError(f"{path}: column {column} holds a value that is not a "
                             f"number") from None
    return data


def collision_rate(time, counts, max_points=RATE_POINTS):
    """(midpoints [s], collisions per simulated second) of cumulative ``counts`` sampled
    at ``time`` [s], over at most ``max_points`` equal runs of frames (one frame each
    for short runs); intervals of zero length are left out."""
    time, counts = np.asarray(time, float), np.asarray(counts, float)
    picks = np.unique(np.linspace(0, len(time) - 1, min(len(time), max_points + 1))
                      .astype(int))
    time, counts = time[picks], counts[picks]
    dt = np.diff(time)
    keep = dt > 0
    return (0.5 * (time[1:] + time[:-1]))[keep], (np.diff(counts)[keep] / dt[keep])


def _pyplot():
    """matplotlib.pyplot on the Agg backend (PlotUnavailable with the pip command)."""
    try:
        import matplotlib
    except ImportError:
        raise PlotUnavailable("plotting needs matplotlib: pip install "
                              "'taichi_spheres[plot]' (or pip install matplotlib)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _energy_panel(ax, d):
    t = d["time"]
    ax.plot(t, d["kinetic"], label="kinetic")
    ax.plot(t, d["potential"], label="potential")
    ax.plot(t, d["total"], "k", lw=1.5, label="total (kinetic + potential)")
    for column, label in LOSSES:
        if np.any(d[column] != 0):
            ax.plot(t, d[column], "--", label=label)
    ax.set_ylabel("energy [J]")
    ax.legend(fontsize=8, loc="best")


def _rate_panel(ax, d):
    for column, label in (("pair_collisions", "pair"), ("wall_collisions", "wall")):
        mid, rate = collision_rate(d["time"], d[column])
        ax.plot(mid, rate, drawstyle="steps-mid", label=label)
    ax.set_ylabel("collisions per s")
    ax.legend(fontsize=8, loc="best")


def _overlap_panel(ax, d):
    t, overlap = d["time"], d["max_overlap"]
    positive = overlap > 0
    if positive.any():
        ax.semilogy(t[positive], overlap[positive], color="C3")
    else:
        ax.text(0.5, 0.5, "no overlap left after any step", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_ylabel("largest overlap so far\n(fraction of contact distance)")


def plot_diagnostics(csv_path: str, out: str | None = None, title: str | None = None) -> str:
    """Write the PNG of ``csv_path``'s diagnostics to ``out`` (default: the CSV's path
    with .png) and return its path. ValueError for a bad CSV or output path,
    PlotUnavailable without matplotlib."""
    from .output import check_writable
    out = out or os.path.splitext(csv_path)[0] + ".png"
    if not out.lower().endswith(".png"):
        raise ValueError(f"plot output must end in .png, got {out}")
    check_writable(out)
    data = read_diagnostics(csv_path)
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=FIGSIZE, sharex=True)
    try:
        _energy_panel(axes[0], data)
        _rate_panel(axes[1], data)
        _overlap_panel(axes[2], data)
        for ax in axes:
            ax.grid(True, alpha=0.3)
        axes[-1].set_xlabel("simulated time [s]")
        axes[0].set_title(title or os.path.basename(csv_path))
        fig.tight_layout()
        fig.savefig(out, dpi=DPI)
    finally:
        plt.close(fig)
    return out
