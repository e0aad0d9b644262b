"""The measuring tools that also run on a GPU (tools/contact_solver.py --beds-only,
tools/silo_large.py, tools/kernel_profile.py): a GPU arch where a tool runs only on the
CPU is refused before Taichi starts, and GPU rows are labelled by their arch. No
timings are asserted."""
import argparse
import os
import sys
import types

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))

import contact_solver  # noqa: E402  (tools/contact_solver.py)
import kernel_profile  # noqa: E402  (tools/kernel_profile.py)
import silo_large  # noqa: E402  (tools/silo_large.py)


def test_contact_solver_runs_only_its_bed_on_a_gpu(capsys):
    """The pour, columns and error tables are single-thread CPU figures: --arch cuda
    without --beds-only is a usage error, not a run."""
    with pytest.raises(SystemExit) as exit_info:
        contact_solver.main(["--arch", "cuda"])
    assert exit_info.value.code == 2
    assert "--beds-only" in capsys.readouterr().err


def test_bed_rows_name_the_arch_and_the_beds_that_ran_out_of_time():
    bed = dict(n=100820, wall_per_s=1.5, steps=22, sweeps=100.0, vmax=1e-3, overlap=2e-5)
    args = argparse.Namespace(bed_time=0.3, arch="cuda", bed_n=100000)
    lines = contact_solver.beds_table(args, {(None, "defaults"): bed,
                                             (None, contact_solver.FAST): {"timeout": 60.0}})
    rows = [line for line in lines if line.startswith("| 1") or line.startswith("| about")]
    assert rows[0].startswith("| 100820 spheres | CUDA | defaults")
    assert "| 1.50 | 22 | 100.0 |" in rows[0]
    assert rows[1].startswith("| about 100000 spheres | CUDA |")
    assert "not done in 60 s" in rows[1]


def test_silo_rows_name_the_arch_or_the_threads():
    a = types.SimpleNamespace(radius=0.001, silo_radius=0.04, orifice=8.0, settle=0.0,
                              duration=0.02, arch="cuda")
    row = dict(n=100000, threads=None, wall_per_sim=12.3456, steps=42, rows=152843.0,
               sweeps=100.0, discharged=0, overlap=4.2e-4, batch=None, digest="ab12")
    text = silo_large.report([row, dict(row, batch=8)], ["--arch", "cuda"], a)
    assert "| CUDA | default | 12.35 | 42 | 152843 | 100 | 0 | 4.2e-04 | ab12 |" in text
    assert "| CUDA | 8 | 12.35 |" in text
    a.arch = "cpu"
    text = silo_large.report([dict(row, threads=2, wall_per_sim=1084.2)], [], a)
    assert "| 2 | default | 1084 | 42 |" in text


def test_kernel_profile_needs_a_run_to_profile(capsys):
    with pytest.raises(SystemExit):
        kernel_profile.main(["--arch", "cuda"])
    assert "--gas N" in capsys.readouterr().err


@pytest.mark.parametrize("argv, words", [
    (["--arch", "cuda", "--beds-only", "--threads", "2"], "--threads sets CPU threads"),
    (["--threads", "0"], "--threads must be at least 1"),
    (["--beds-only", "--child-timeout", "0"], "--child-timeout must be > 0"),
    (["--bed-settings", "relaxed"], "go with --beds-only"),
    (["--beds-only", "--quick"], "--quick does not go with --beds-only"),
    (["--arch", "cdua", "--beds-only"], "invalid choice: 'cdua'"),
])
def test_contact_solver_options_that_do_not_go_together(capsys, argv, words):
    with pytest.raises(SystemExit):
        contact_solver.main(argv)
    assert words in capsys.readouterr().err


@pytest.mark.parametrize("argv, words", [
    (["--silo", "--arch", "cuda"], "--silo runs on the CPU in f64"),
    (["--gas", "100", "--silo"], "give one of"),
    (["--gas", "-5"], "take a positive sphere count"),
    (["--silo-large", "-5"], "take a positive sphere count"),
    (["--silo-large", "1000", "--silo"], "give one of"),
    (["--silo-large", "1000", "--precision", "f32"], "--silo-large runs in f64"),
    (["--silo-large", "1000", "--arch", "vulkan"], "on cpu or cuda"),
    (["--gas", "100", "--step-fraction", "0.2"], "--step-fraction goes with --scene"),
    (["--gas", "100", "--tuning", "relaxation=1.0"], "--tuning goes with --silo or --scene"),
    (["--scene", "scenes/pour.toml", "--step-fraction", "2"], "step_fraction must be"),
    (["--scene", "scenes/pour.toml", "--tuning", "relaxation"], "write NAME=VALUE"),
    (["--scene", "scenes/pour.toml", "--step-fraction", "0.2", "--write"],
     "--write keeps the defaults' profile"),
])
def test_kernel_profile_options_that_do_not_go_together(capsys, argv, words):
    with pytest.raises(SystemExit):
        kernel_profile.main(argv)
    assert words in capsys.readouterr().err


def test_silo_large_takes_threads_on_the_cpu_only(capsys):
    with pytest.raises(SystemExit):
        silo_large.main(["--arch", "cuda", "--threads", "2"])
    assert "only with --arch cpu" in capsys.readouterr().err
