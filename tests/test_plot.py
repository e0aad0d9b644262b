"""``taichi-spheres plot RUN.csv``: the PNG of a short run's diagnostics, and bad input."""
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from taichi_spheres import plot

pytest.importorskip("matplotlib")

#: a real scene (five spheres under gravity, walls, inelastic), run for 0.5 s
SCENE = Path(__file__).resolve().parent.parent / "scenes" / "seed_five.toml"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "taichi_spheres.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory):
    """The diagnostics CSV of a 0.5 s run of scenes/seed_five.toml (16 frames)."""
    d = tmp_path_factory.mktemp("plot")
    r = cli("run", str(SCENE), "-o", "five.mp4", "--no-video", "--quiet", "--duration", "0.5",
            cwd=d)
    assert r.returncode == 0, r.stderr
    return d / "five.csv"


def png_size(path):
    """(width, height) [pixels] from a PNG's IHDR chunk; AssertionError if not a PNG."""
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE and head[12:16] == b"IHDR", f"{path} is not a PNG"
    return struct.unpack(">II", head[16:24])


def test_plot_writes_a_png_next_to_the_csv(run_csv):
    r = cli("plot", run_csv.name, cwd=run_csv.parent)
    assert r.returncode == 0, r.stderr
    out = run_csv.with_suffix(".png")
    assert f"wrote {out.name}" in r.stderr
    width, height = png_size(out)
    assert (width, height) == (round(plot.FIGSIZE[0] * plot.DPI),
                               round(plot.FIGSIZE[1] * plot.DPI))
    assert 10_000 < out.stat().st_size < 300_000       # three panels of lines, not blank


def test_plot_to_a_named_file(run_csv, tmp_path):
    out = tmp_path / "energy.png"
    r = cli("plot", str(run_csv), "-o", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert png_size(out)[0] > 0


def test_missing_csv_exits_2_naming_it(tmp_path):
    r = cli("plot", "nowhere.csv", cwd=tmp_path)
    assert r.returncode == 2
    assert "no such file: nowhere.csv" in r.stderr
    assert not (tmp_path / "nowhere.png").exists()


def test_csv_without_the_columns_exits_2_naming_them(tmp_path):
    (tmp_path / "other.csv").write_text("time,kinetic\n0.0,1.0\n")
    r = cli("plot", "other.csv", cwd=tmp_path)
    assert r.returncode == 2
    assert "other.csv lacks the column(s) potential, total" in r.stderr


def test_csv_with_a_value_that_is_not_a_number(tmp_path):
    columns = ",".join(plot.REQUIRED_COLUMNS)
    values = ",".join(["0"] * (len(plot.REQUIRED_COLUMNS) - 1) + ["oops"])
    (tmp_path / "bad.csv").write_text(f"{columns}\n{values}\n")
    with pytest.raises(ValueError, match="bad.csv: column energy_contacts"):
        plot.read_diagnostics(str(tmp_path / "bad.csv"))


def test_collision_rate_per_frame_interval():
    mid, rate = plot.collision_rate([0.0, 0.5, 1.0, 1.0], [0, 2, 6, 6])
    assert mid.tolist() == [0.25, 0.75] and rate.tolist() == [4.0, 8.0]


def test_collision_rate_of_a_long_run_is_averaged():
    t = np.linspace(0.0, 10.0, 10_001)
    mid, rate = plot.collision_rate(t, 3.0 * np.arange(t.size), max_points=100)
    assert len(mid) == 100 and np.allclose(rate, 3000.0)


def test_without_matplotlib_the_error_names_the_pip_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)      # import fails
    with pytest.raises(plot.PlotUnavailable, match=r"pip install 'taichi_spheres\[plot\]'"):
        plot._pyplot()


def test_a_csv_without_the_optional_columns_reads_them_as_zero(run_csv, tmp_path):
    """A CSV written before energy_discharged existed still plots."""
    lines = run_csv.read_text().splitlines()
    header = lines[0].split(",")
    drop = [header.index(c) for c in plot.OPTIONAL_COLUMNS]
    old = [",".join(v for k, v in enumerate(line.split(",")) if k not in drop) for line in lines]
    (tmp_path / "old.csv").write_text("\n".join(old) + "\n")
    data = plot.read_diagnostics(str(tmp_path / "old.csv"))
    assert all(not data[c].any() and len(data[c]) == len(lines) - 1
               for c in plot.OPTIONAL_COLUMNS)
    assert png_size(Path(plot.plot_diagnostics(str(tmp_path / "old.csv"))))[0] > 0
