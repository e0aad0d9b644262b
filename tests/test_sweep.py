"""Parameter sweeps: the grid, rows with errors, a real Dask LocalCluster of two worker
processes, and the command line (its CSV, written as runs end, kept on Ctrl-C)."""
import csv
import os
import subprocess
import sys

import pytest

import taichi_spheres as ts
from taichi_spheres import builders
from taichi_spheres.cli import split_values, sweep_grid
from taichi_spheres.sweeps import grid_runs

from ctrl_c import interrupt_after_lines

GRID = {"restitution": [1.0, 0.8, 1.5], "step_fraction": [0.1]}


def small_gas():
    return builders.gas(27, packing=0.2, radius=0.05, restitution=0.9)


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_grid_runs_every_combination_and_names_bad_keys():
    runs = grid_runs({"a": [1, 2], "b": ["x", "y"]})
    assert runs == [{"a": 1, "b": "x"}, {"a": 1, "b": "y"}, {"a": 2, "b": "x"},
                    {"a": 2, "b": "y"}]
    with pytest.raises(ValueError, match="grid\\['a'\\] has no values"):
        grid_runs({"a": []})
    with pytest.raises(ValueError, match="unknown sweep parameter 'restitutoin'"):
        ts.sweep(small_gas(), {"restitutoin": [0.5]}, duration=0.1, serial=True)


@pytest.mark.own_runtime
def test_serial_sweep_reports_failures_in_their_rows(tmp_path):
    seen = []
    rows = ts.sweep(small_gas(), GRID, duration=0.1, serial=True, out=tmp_path / "s.csv",
                    measure=lambda sim: {"kinetic": ts.observe.kinetic_energy(sim.state())},
                    on_row=seen.append)
    assert [r["run"] for r in rows] == [0, 1, 2] and len(seen) == 3
    assert rows[0]["error"] is None and rows[1]["error"] is None
    assert rows[2]["error"].startswith("ValueError: restitution must be in [0, 1]")
    assert rows[0]["steps"] > 0 and rows[0]["time"] == pytest.approx(0.1)
    assert rows[0]["kinetic"] == pytest.approx(rows[0]["energy_kinetic"])
    assert rows[1]["energy_pair_restitution"] > 0 == rows[0]["energy_pair_restitution"]
    table = read_csv(tmp_path / "s.csv")
    assert [int(r["run"]) for r in table] == [0, 1, 2]
    assert table[2]["error"].startswith("ValueError") and table[2]["steps"] == ""


@pytest.mark.own_runtime
def test_local_cluster_of_two_processes_gives_the_serial_rows():
    pytest.importorskip("distributed")
    grid = {"restitution": [1.0, 0.8], "step_fraction": [0.1, 0.05]}
    serial = ts.sweep(small_gas(), grid, duration=0.1, serial=True)
    rows = ts.sweep(small_gas(), grid, duration=0.1, workers=2,
                    measure=lambda sim: {"pid": os.getpid()})
    assert len(rows) == 4 and all(r["error"] is None for r in rows)
    assert all(r["pid"] != os.getpid() for r in rows)
    for mine, theirs in zip(rows, serial):
        for key in ("steps", "pair_collisions", "energy_current"):
            assert mine[key] == theirs[key], key


def test_set_values_parse_as_toml():
    assert split_values("0.5,0.7") == [0.5, 0.7]
    assert split_values("[0, 0, -9.81],[0, 0, 0]") == [[0, 0, -9.81], [0, 0, 0]]
    assert split_values("normal,smid,true") == ["normal", "smid", True]
    assert sweep_grid(["restitution=0.5,1", "fused=false"]) == {"restitution": [0.5, 1],
                                                               "fused": [False]}
    with pytest.raises(ValueError, match="KEY=VALUE1"):
        sweep_grid(["restitution"])
    with pytest.raises(ValueError, match="--set restitution: empty value"):
        sweep_grid(["restitution="])


SEED_FIVE = os.path.join(os.path.dirname(__file__), "..", "scenes", "seed_five.toml")


def sweep_args(*args):
    return [sys.executable, "-m", "taichi_spheres.cli", "sweep", "s.toml", *args]


def test_cli_sweep_writes_a_row_per_run(tmp_path):
    (tmp_path / "s.toml").write_text(open(SEED_FIVE).read())
    r = subprocess.run(sweep_args("--set", "restitution=0.5,2", "--set", "step_fraction=0.1",
                                  "--serial", "--duration", "0.1", "--out", "s.csv"),
                       cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 1, r.stderr          # one run failed: its row says why
    rows = read_csv(tmp_path / "s.csv")
    assert [row["restitution"] for row in rows] == ["0.5", "2"]
    assert rows[0]["error"] == "" and float(rows[0]["time"]) == pytest.approx(0.1)
    assert "restitution must be in [0, 1]" in rows[1]["error"]
    assert "sweep: 2/2 done" in r.stderr and "2 runs, 1 failed" in r.stderr


def test_interrupted_cli_sweep_keeps_the_finished_rows(tmp_path):
    (tmp_path / "s.toml").write_text(open(SEED_FIVE).read())
    path = tmp_path / "s.csv"
    code, err = interrupt_after_lines(["sweep", "s.toml", "--set", "restitution="
                                       + ",".join(["0.5"] * 200), "--serial", "--duration", "0.1",
                                       "--out", "s.csv", "--quiet"], tmp_path, path, 3)
    assert code == 130, err
    rows = read_csv(path)
    assert 3 <= len(rows) < 200 and all(row["error"] == "" for row in rows)
