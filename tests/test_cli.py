"""The command line end to end, in subprocesses: video, CSV, bad input, interrupt, resume."""
import csv
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from taichi_spheres.output import CSV_COLUMNS

from ctrl_c import interrupt, interrupt_after_lines, start_cli

TINY = """
name = "tiny"
[physics]
restitution = 0.9
[box]
wall_restitution = 0.9
[run]
duration = 0.5
fps = 20
[render]
width = 160
height = 128
[[lattice]]
lo = [0.1, 0.1, 0.5]
hi = [0.9, 0.9, 0.9]
spacing = 0.2
radius = 0.05
speed = 1.0
"""


def _vulkan_available():
    code = ("import taichi as ti; ti.init(arch=ti.cpu, log_level=ti.ERROR); "
            "ti.ui.Window('t', (16, 16), show_window=False)")
    return subprocess.run([sys.executable, "-c", code], capture_output=True,
                          timeout=120).returncode == 0


@pytest.fixture(scope="module")
def vulkan():
    if not _vulkan_available():
        pytest.skip("no Vulkan here (install mesa-vulkan-drivers)")
    return True


def cli(*args, cwd, timeout=600):
    return subprocess.run([sys.executable, "-m", "taichi_spheres.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)


def read_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return rows


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory, vulkan):
    """One full run with checkpoints and snapshots, shared by several tests."""
    d = tmp_path_factory.mktemp("cli")
    (d / "tiny.toml").write_text(TINY)
    r = cli("run", "tiny.toml", "-o", "full.mp4", "--npz", "--checkpoint-every", "4", cwd=d)
    assert r.returncode == 0, r.stderr
    return d, r


def test_run_writes_video_csv_and_snapshots(tiny_run):
    import imageio.v2 as imageio
    d, r = tiny_run
    frames = [f for f in imageio.get_reader(str(d / "full.mp4")).iter_data()]
    assert len(frames) == 11                      # t = 0, 0.05, ..., 0.5
    assert frames[0].shape == (128, 160, 3)
    assert all(f.std() > 1.0 for f in frames), "blank frame"
    assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).mean() > 0.5, "no motion"
    rows = read_csv(d / "full.csv")
    assert list(rows[0]) == CSV_COLUMNS and len(rows) == 11
    times = [float(row["time"]) for row in rows]
    assert times == [k / 20 for k in range(11)]
    # counters are cumulative and agree with the summary line
    pairs = [int(row["pair_collisions"]) for row in rows]
    assert pairs == sorted(pairs)
    assert f"{pairs[-1]} pair + {rows[-1]['wall_collisions']} wall" in r.stderr
    snap = np.load(d / "full.npz")
    assert snap["x"].shape == (11, 32, 3)
    assert "arch cpu" in r.stderr and "GGUI offscreen" in r.stderr


def test_csv_matches_the_python_api(tiny_run, arch):
    import taichi_spheres as ts
    d, _ = tiny_run
    rows = read_csv(d / "full.csv")
    sim = ts.Simulation(ts.load_scene(str(d / "tiny.toml")), arch="cpu")
    for k in range(11):                  # frames land on k / fps, as in the CLI
        sim.advance_to(k / 20)
    st = sim.state()
    last = rows[-1]
    assert int(last["steps"]) == sim.stats["steps"]
    assert int(last["pair_collisions"]) == sim.stats["pair_collisions"]
    assert float(last["kinetic"]) == ts.observe.kinetic_energy(st)
    snap = np.load(d / "full.npz")
    np.testing.assert_allclose(snap["x"][-1], st.x, rtol=0, atol=1e-6)   # npz holds float32


def test_resume_gives_identical_results(tiny_run):
    d, _ = tiny_run
    # an interrupted run: stop at 0.3 s with checkpoints every 4 frames (frame 3 = 0.15 s)
    r = cli("run", "tiny.toml", "-o", "part.mp4", "--duration", "0.3", "--checkpoint-every",
            "4", "--npz", cwd=d)
    assert r.returncode == 0, r.stderr
    r = cli("run", "tiny.toml", "-o", "part.mp4", "--resume", "part.ckpt.npz", "--npz", cwd=d)
    assert r.returncode == 0, r.stderr
    full, part = read_csv(d / "full.csv"), read_csv(d / "part.csv")
    assert full == part
    for key in ("x", "v", "time"):      # the frames before the checkpoint are kept
        np.testing.assert_array_equal(np.load(d / "full.npz")[key], np.load(d / "part.npz")[key])
    import imageio.v2 as imageio
    assert imageio.get_reader(str(d / "part.mp4")).count_frames() == 11


def test_resume_refuses_another_scene(tiny_run):
    d, _ = tiny_run
    (d / "other.toml").write_text(TINY.replace("speed = 1.0", "speed = 2.0"))
    r = cli("run", "other.toml", "-o", "other.mp4", "--resume", "full.ckpt.npz", cwd=d)
    assert r.returncode == 2 and "different scene" in r.stderr


def test_one_thread_writes_the_same_diagnostics(tiny_run):
    """--threads 1 changes the speed, not the numbers."""
    d, _ = tiny_run
    r = cli("run", "tiny.toml", "-o", "one.mp4", "--no-video", "--threads", "1", "--quiet",
            cwd=d)
    assert r.returncode == 0, r.stderr
    assert read_csv(d / "one.csv") == read_csv(d / "full.csv")


def test_fused_run_writes_the_same_diagnostics(tiny_run):
    """--fused (one kernel per step on the CPU) changes the speed, not the numbers."""
    d, _ = tiny_run
    r = cli("run", "tiny.toml", "-o", "fused.mp4", "--no-video", "--fused", "--quiet", cwd=d)
    assert r.returncode == 0, r.stderr
    assert read_csv(d / "fused.csv") == read_csv(d / "full.csv")


def test_interrupt_keeps_a_playable_video(tmp_path, vulkan):
    import imageio.v2 as imageio
    (tmp_path / "tiny.toml").write_text(TINY.replace("duration = 0.5", "duration = 600.0"))
    code, err = interrupt_after_lines(["run", "tiny.toml", "-o", "long.mp4", "--quiet"],
                                      tmp_path, tmp_path / "long.csv", 5)
    assert code == 130, err
    assert "interrupted at frame" in err
    n = imageio.get_reader(str(tmp_path / "long.mp4")).count_frames()
    assert n >= 4
    assert not (tmp_path / "imgui.ini").exists()


BAD_SCENES = {
    "unknown key": ("[box]\nperiodik = true\n", ["box.periodik", "box.periodic"]),
    "wrong type": ("[physics]\nrestitution = \"high\"\n", ["physics.restitution"]),
    "negative radius": ("", ["radius"]),
    "size": ("[render]\nwidth = 100\n", ["render.width", "16"]),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_exits_2_without_output(tmp_path, case):
    extra, words = BAD_SCENES[case]
    sphere = "[[spheres]]\nx = [0.5, 0.5, 0.5]\nradius = %s\n" % ("-0.1" if case == "negative radius" else "0.1")
    (tmp_path / "bad.toml").write_text(extra + sphere)
    r = cli("run", "bad.toml", "-o", "bad.mp4", cwd=tmp_path, timeout=120)
    assert r.returncode == 2, r.stderr
    for w in words:
        assert w in r.stderr
    assert not any(p.name.startswith("bad.") and p.suffix != ".toml" for p in tmp_path.iterdir())


def test_all_problems_reported_at_once(tmp_path):
    text = ("[box]\nperiodik = true\n[physics]\nrestitution = 2.0\n[render]\nheight = 50\n"
            "[[spheres]]\nx = [0.5, 0.5, 0.5]\nradius = 0.1\n"
            "[[spheres]]\nx = [0.55, 0.5, 0.5]\nradius = 0.1\n")
    (tmp_path / "bad.toml").write_text(text)
    r = cli("run", "bad.toml", cwd=tmp_path, timeout=120)
    assert r.returncode == 2
    for w in ("box.periodik", "restitution", "render.height"):
        assert w in r.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_overlap_and_outside_box_name_the_spheres(tmp_path):
    text = ("[[spheres]]\nx = [0.5, 0.5, 0.5]\nradius = 0.1\n"
            "[[spheres]]\nx = [0.55, 0.5, 0.5]\nradius = 0.1\n")
    (tmp_path / "a.toml").write_text(text)
    r = cli("run", "a.toml", "-o", "a.mp4", cwd=tmp_path, timeout=120)
    assert r.returncode == 2 and "spheres 0 and 1" in r.stderr
    (tmp_path / "b.toml").write_text("[[spheres]]\nx = [0.95, 0.5, 0.5]\nradius = 0.1\n")
    r = cli("run", "b.toml", "-o", "b.mp4", cwd=tmp_path, timeout=120)
    assert r.returncode == 2 and "sphere 0" in r.stderr


def test_unwritable_output_fails_before_simulating(tmp_path):
    (tmp_path / "ok.toml").write_text("[[spheres]]\nx = [0.5, 0.5, 0.5]\nradius = 0.1\n")
    r = cli("run", "ok.toml", "-o", "no/such/dir/x.mp4", cwd=tmp_path, timeout=120)
    assert r.returncode == 2 and "does not exist" in r.stderr


def test_duration_between_frames_ends_with_a_frame_at_the_duration(tmp_path):
    """A duration that is not a whole number of frame intervals is run to its end: the
    frames fall on k / fps, and the last one on the duration itself."""
    (tmp_path / "tiny.toml").write_text(TINY)
    r = cli("run", "tiny.toml", "-o", "x.mp4", "--no-video", "--duration", "0.52", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    times = [float(row["time"]) for row in read_csv(tmp_path / "x.csv")]
    assert times == [k / 20 for k in range(11)] + [0.52]
    assert "(12 frames)" in r.stderr and "for 0.52 s simulated" in r.stderr
    r = cli("run", "tiny.toml", "-o", "y.mp4", "--no-video", "--duration", "0.02", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [float(row["time"]) for row in read_csv(tmp_path / "y.csv")] == [0.0, 0.02]


SINK = """
name = "sink"
[physics]
gravity = [0.0, 0.0, -9.81]
restitution = 0.5
[box]
hi = [0.1, 0.1, 0.2]
[run]
duration = 0.3
fps = 20
[[plane]]
point = [0.05, 0.05, 0.05]
normal = [0.0, 0.0, 1.0]
hole = 0.02
[[sink]]
low = [0.0, 0.0, 0.0]
high = [0.1, 0.1, 0.03]
[[lattice]]
lo = [0.03, 0.03, 0.06]
hi = [0.07, 0.07, 0.12]
spacing = 0.011
radius = 0.005
"""


def test_snapshots_and_csv_of_a_scene_with_a_sink(tmp_path):
    """The .npz keeps the scene's sphere order (NaN rows for the spheres a sink took
    out), and the CSV books the energy they took: total plus every energy_* column stays
    at its first value."""
    import taichi_spheres as ts
    (tmp_path / "sink.toml").write_text(SINK)
    r = cli("run", "sink.toml", "-o", "s.mp4", "--no-video", "--npz", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    rows, snap = read_csv(tmp_path / "s.csv"), np.load(tmp_path / "s.npz")
    n = len(snap["radius"])
    gone = [int(row["discharged"]) for row in rows]
    assert gone[-1] > 0
    assert snap["x"].shape == (len(rows), n, 3)
    assert [int(np.isnan(x[:, 0]).sum()) for x in snap["x"]] == gone
    books = [float(row["total"]) + sum(float(row[c]) for c in row if c.startswith("energy_"))
             for row in rows]
    assert float(rows[-1]["energy_discharged"]) > 0
    np.testing.assert_allclose(books, books[0], rtol=1e-9)
    sim = ts.Simulation(ts.load_scene(str(tmp_path / "sink.toml")), arch="cpu")
    for k in range(len(rows)):
        sim.advance_to(k / 20)
    np.testing.assert_allclose(snap["x"][-1][sim.sphere_ids], sim.state().x, rtol=0, atol=1e-6)
    # a run continued from a checkpoint keeps the snapshots before it
    r = cli("run", "sink.toml", "-o", "p.mp4", "--no-video", "--npz", "--duration", "0.2",
            "--checkpoint-every", "3", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cli("run", "sink.toml", "-o", "p.mp4", "--no-video", "--npz", "--resume",
            "p.ckpt.npz", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    part = np.load(tmp_path / "p.npz")
    for key in ("x", "v", "time"):
        np.testing.assert_array_equal(part[key], snap[key])
    assert read_csv(tmp_path / "p.csv") == rows


def test_resume_refuses_what_it_cannot_continue(tmp_path):
    """A checkpoint on the extra last frame of a duration off the frame grid is no frame
    of a longer run; --npz needs the snapshots before the checkpoint; a CSV written
    before a column existed keeps its rows under their own columns."""
    (tmp_path / "tiny.toml").write_text(TINY)
    r = cli("run", "tiny.toml", "-o", "a.mp4", "--no-video", "--duration", "0.52",
            "--checkpoint-every", "4", cwd=tmp_path)        # checkpoints frame 11, t = 0.52
    assert r.returncode == 0, r.stderr
    r = cli("run", "tiny.toml", "-o", "a.mp4", "--no-video", "--duration", "0.7",
            "--resume", "a.ckpt.npz", cwd=tmp_path)
    assert r.returncode == 2 and "not at frame 11 of this run" in r.stderr
    r = cli("run", "tiny.toml", "-o", "a.mp4", "--no-video", "--resume", "a.ckpt.npz",
            cwd=tmp_path)                                     # 0.5 s: ends before frame 11
    assert r.returncode == 2 and "nothing is left to run" in r.stderr
    r = cli("run", "tiny.toml", "-o", "b.mp4", "--no-video", "--duration", "0.3",
            "--checkpoint-every", "4", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = cli("run", "tiny.toml", "-o", "b.mp4", "--no-video", "--npz", "--resume", "b.ckpt.npz",
            cwd=tmp_path)
    assert r.returncode == 2 and "b.npz does not exist" in r.stderr
    rows = read_csv(tmp_path / "b.csv")
    with open(tmp_path / "b.csv", "w", newline="") as fh:      # as written before the column
        old = [c for c in CSV_COLUMNS if c != "energy_discharged"]
        writer = csv.DictWriter(fh, old, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    r = cli("run", "tiny.toml", "-o", "b.mp4", "--no-video", "--resume", "b.ckpt.npz",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    kept = read_csv(tmp_path / "b.csv")[:4]
    assert [row["rotational"] for row in kept] == [row["rotational"] for row in rows[:4]]
    assert all(row["energy_discharged"] == "nan" for row in kept)


def test_output_cut_short_by_its_reader_ends_quietly(tmp_path):
    """taichi-spheres info SCENE | head: no traceback when the reader stops early."""
    (tmp_path / "tiny.toml").write_text(TINY)
    p = subprocess.Popen([sys.executable, "-m", "taichi_spheres.cli", "info", "tiny.toml"],
                         cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                     # the reader is gone before the first line
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 1
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_info_lists_compiled_features(tmp_path):
    root = os.path.join(os.path.dirname(__file__), "..")
    r = cli("info", os.path.join(root, "scenes", "gas.toml"), cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "spheres: 4096" in r.stdout
    assert "gravity: off (compiled out)" in r.stdout
    assert "MiB" in r.stdout
    # 4,096 spheres on the CPU: serial light loops, parallel detection from near lists
    assert "schedule (cpu):" in r.stdout
    assert "detection: parallel, from near lists" in r.stdout
    assert "drift and grid build: serial" in r.stdout


def test_schedule_follows_sphere_count_arch_and_options():
    """engine.Schedule: which path a step takes, from the sphere count, the arch and the
    Performance thresholds (no Taichi needed)."""
    from taichi_spheres.config import DEFAULT
    from taichi_spheres.engine import Schedule
    perf = DEFAULT.performance
    small = Schedule.plan(1000, True, False, True, perf)
    assert small.serial_heavy and small.serial_light and small.fused and not small.serial_few
    mid = Schedule.plan(50_000, True, True, True, perf)
    assert mid.serial_light and not mid.serial_heavy and mid.serial_few and not mid.fused
    gpu = Schedule.plan(1000, False, True, True, perf)
    assert not (gpu.serial_light or gpu.serial_heavy or gpu.serial_few or gpu.fused)
    assert "one parallel launch per colour" in " ".join(gpu.describe())
    big = Schedule.plan(500_000, True, True, False, DEFAULT.with_(serial_light_below=10**6)
                        .performance)
    assert big.serial_light


def test_cli_choices_match_the_runtime():
    """The CLI spells out the arches and compile modes (parsing must not import Taichi):
    they are the runtime's, plus "auto"."""
    from taichi_spheres import cli, runtime
    assert cli.ARCHS == runtime.ARCHS
    assert set(cli.COMPILE_CHOICES) == set(runtime.COMPILE_MODES) | {"auto"}


ROOT = os.path.join(os.path.dirname(__file__), "..")
SEED_FIVE = open(os.path.join(ROOT, "scenes", "seed_five.toml")).read()


def seed_five(tmp_path, *changes, name="s.toml"):
    """scenes/seed_five.toml with lines changed (pairs of old, new), as tmp_path/name."""
    text = SEED_FIVE
    for old, new in changes:
        assert old in text
        text = text.replace(old, new, 1)
    (tmp_path / name).write_text(text)
    return name


def test_help_and_info_print_no_taichi_banner(tmp_path):
    for args in (["--help"], ["run", "--help"]):
        r = cli(*args, cwd=tmp_path, timeout=120)
        assert r.returncode == 0 and "[Taichi]" not in r.stdout + r.stderr
    assert "(default: None)" not in r.stdout
    assert "(default: out/<scene name>.mp4)\n" in r.stdout.replace("\n" + " " * 24, " ")
    code = ("import sys, contextlib, io\nimport taichi_spheres as ts, taichi_spheres.cli as c\n"
            "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "    c.main(['run', '--help'])\nprint('taichi' in sys.modules, ts.Scene.__name__)\n"
            "print(ts.Simulation is ts.simulation.Simulation, ts.State.__name__, "
            "sorted(set(ts.__all__) - set(dir(ts))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    ours = [line for line in r.stdout.splitlines() if not line.startswith("[Taichi]")]
    assert ours == ["False Scene", "True State []"], r.stdout + r.stderr
    r = cli("info", seed_five(tmp_path), cwd=tmp_path, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("scene: seed_five"), r.stdout + r.stderr
    assert "work: about 1.2e+04 steps" in r.stdout and "wall time: about" in r.stdout


@pytest.mark.parametrize("old, new, words", [
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -1e12]",
     ["gravity [0, 0, -1e+12] m/s^2", "sphere 2", "--force"]),
    ("v = [1.5, 0.8, 1.0]", "v = [1e8, 0.8, 1.0]", ["sphere 0 moves at 1e+08 m/s", "--force"]),
    ("fps = 30", "fps = 1e9", ["fps", "--force"]),
])
def test_runs_beyond_the_work_limit_are_refused(tmp_path, old, new, words):
    r = cli("run", seed_five(tmp_path, (old, new)), "--no-video", "--duration", "0.2", "--quiet",
            "-o", "s.mp4", cwd=tmp_path, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    for w in words:
        assert w in r.stderr
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("new, args, words", [
    ("v = [1e300, 0.8, 1.0]", [], ["speed of sphere 0 (1e+300 m/s) overflows f64"]),
    ("v = [1e19, 0.8, 1.0]", ["--precision", "f32"],
     ["error: speed of sphere 0 (1e+19 m/s) overflows f32", "at most 1.2e+18 m/s\n"]),
])
def test_speeds_the_precision_cannot_hold_exit_2(tmp_path, new, args, words):
    r = cli("run", seed_five(tmp_path, ("v = [1.5, 0.8, 1.0]", new)), "--no-video", "--quiet",
            "--duration", "0.2", *args, cwd=tmp_path, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    for w in words:
        assert w in r.stderr


@pytest.mark.parametrize("old, new, words", [
    ("radius = 0.06\n", "radious = 0.06\n",
     ["unknown key 'spheres[0].radious' (did you mean 'spheres[0].radius'?)"]),
    ("colour = [0.90, 0.30, 0.25]", "colour = [2.0, 0.3, 0.25]", ["spheres[0].colour", "[0, 1]"]),
    ("radius = 0.06\n", "radius = 1e-300\n", ["radius of sphere 0 (1e-300 m) is below what f64"]),
])
def test_scene_mistakes_exit_2_naming_the_key(tmp_path, old, new, words):
    r = cli("run", seed_five(tmp_path, (old, new)), "--no-video", "--quiet", cwd=tmp_path,
            timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "1 problem(s)" in r.stderr and "missing" not in r.stderr and "mass" not in r.stderr
    for w in words:
        assert w in r.stderr


def test_many_frames_show_their_work_up_front(tmp_path):
    """fps = 1e6 for 0.2 s: legitimate, slow, and said before it starts."""
    name = seed_five(tmp_path, ("duration = 12.0", "duration = 0.2"), ("fps = 30", "fps = 1e6"))
    r = cli("info", name, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "work: about 2.0e+05 steps" in r.stdout and "200001 frames" in r.stdout
    assert "refused" not in r.stdout


def test_quiet_run_prints_status_lines(tmp_path):
    r = cli("run", seed_five(tmp_path), "--no-video", "--quiet", "--duration", "0.1",
            "--status-every", "0.001", "-o", "s.mp4", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "[Taichi] version" not in r.stdout and "(Taichi 1.7" in r.stderr
    assert "work: about" in r.stderr and "timing: " in r.stderr and "ms a step" in r.stderr
    assert "status: frame" in r.stderr and "[#" not in r.stderr


def wait_for(path, text, seconds):
    deadline = time.time() + seconds
    while time.time() < deadline:
        if path.exists() and text in path.read_text():
            return True
        time.sleep(0.2)
    return False


@pytest.mark.skipif(not hasattr(signal, "SIGUSR1"), reason="no SIGUSR1 here")
def test_forced_slow_run_reports_on_sigusr1(tmp_path):
    name = seed_five(tmp_path, ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -1e12]"))
    err = tmp_path / "err.txt"
    with open(err, "w") as fh:
        proc = start_cli(["run", name, "--no-video", "--quiet", "--force", "-o", "s.mp4"],
                         tmp_path, stdout=subprocess.DEVNULL, stderr=fh)
        try:
            assert wait_for(err, "timing:", 300), err.read_text()
            assert "above the limit" in err.read_text()
            proc.send_signal(signal.SIGUSR1)
            assert wait_for(err, "status: frame", 120), err.read_text()
        finally:
            interrupt(proc)
    assert proc.returncode == 130, err.read_text()


# ---- GSD trajectories from the command line ----

def gsd_frames(path):
    import gsd.hoomd
    with gsd.hoomd.open(str(path)) as traj:
        return [(int(f.configuration.step), float(f.log["taichi_spheres/time"][0]),
                 f.particles.position.copy()) for f in traj]


@pytest.fixture(scope="module")
def gsd_run(tmp_path_factory):
    """A run without video writing a trajectory, one frame per video frame."""
    pytest.importorskip("gsd.hoomd")
    d = tmp_path_factory.mktemp("gsd")
    (d / "tiny.toml").write_text(TINY)
    r = cli("run", "tiny.toml", "-o", "full.mp4", "--no-video", "--quiet", "--trajectory",
            "full.gsd", cwd=d)
    assert r.returncode == 0, r.stderr
    assert "full.gsd" in r.stderr
    return d


def test_trajectory_has_one_frame_per_video_frame(gsd_run):
    frames = gsd_frames(gsd_run / "full.gsd")
    rows = read_csv(gsd_run / "full.csv")
    assert [t for _, t, _ in frames] == [float(row["time"]) for row in rows]
    assert [s for s, _, _ in frames] == [int(row["steps"]) for row in rows]
    assert all(x.shape == (32, 3) for _, _, x in frames)


def test_trajectory_every_n_steps(gsd_run):
    r = cli("run", "tiny.toml", "-o", "every.mp4", "--no-video", "--quiet", "--trajectory",
            "every.gsd", "--every", "25", cwd=gsd_run)
    assert r.returncode == 0, r.stderr
    steps = [s for s, _, _ in gsd_frames(gsd_run / "every.gsd")]
    last = int(read_csv(gsd_run / "full.csv")[-1]["steps"])
    assert steps == list(range(0, last + 1, 25))
    assert f"(11 frames; {len(steps)} trajectory frames)" in r.stderr
    assert read_csv(gsd_run / "every.csv") == read_csv(gsd_run / "full.csv")


def test_resumed_run_continues_the_trajectory(gsd_run):
    r = cli("run", "tiny.toml", "-o", "part.mp4", "--no-video", "--quiet", "--duration", "0.3",
            "--checkpoint-every", "4", "--trajectory", "part.gsd", cwd=gsd_run)
    assert r.returncode == 0, r.stderr
    r = cli("run", "tiny.toml", "-o", "part.mp4", "--no-video", "--quiet", "--resume",
            "part.ckpt.npz", "--trajectory", "part.gsd", cwd=gsd_run)
    assert r.returncode == 0, r.stderr
    full, part = gsd_frames(gsd_run / "full.gsd"), gsd_frames(gsd_run / "part.gsd")
    assert [f[:2] for f in part] == [f[:2] for f in full]
    np.testing.assert_array_equal(part[-1][2], full[-1][2])


def test_every_without_a_trajectory_exits_2(tmp_path):
    (tmp_path / "tiny.toml").write_text(TINY)
    r = cli("run", "tiny.toml", "--no-video", "--every", "10", "-o", "e.mp4", cwd=tmp_path,
            timeout=120)
    assert r.returncode == 2 and "--every" in r.stderr and "--trajectory" in r.stderr


def test_interrupt_keeps_a_valid_trajectory(tmp_path):
    """Ctrl-C (a real SIGINT) leaves a GSD file with every frame the CSV has."""
    pytest.importorskip("gsd.hoomd")
    (tmp_path / "tiny.toml").write_text(TINY.replace("duration = 0.5", "duration = 600.0"))
    csv_path = tmp_path / "long.csv"
    code, err = interrupt_after_lines(["run", "tiny.toml", "-o", "long.mp4", "--no-video",
                                       "--quiet", "--trajectory", "long.gsd"],
                                      tmp_path, csv_path, 5)
    assert code == 130, err
    rows = read_csv(csv_path)
    frames = gsd_frames(tmp_path / "long.gsd")
    assert len(frames) == len(rows) >= 5
    assert [t for _, t, _ in frames] == [float(row["time"]) for row in rows]


def test_summary_names_the_substeps_the_steps_ran_in(capsys):
    """The work estimate counts moves (substeps); the summary says how many solver steps
    they were grouped into."""
    from types import SimpleNamespace
    from taichi_spheres import cli
    stats = dict(steps=1120, substeps=12000, pair_collisions=10, wall_collisions=77,
                 max_overlap=0.0, unresolved=0)
    cli._print_summary(SimpleNamespace(stats=stats, sim_seconds=4.8, time=12.0), 3.0)
    assert "1120 steps in 12000 substeps, 10 pair + 77 wall" in capsys.readouterr().err
    cli._print_summary(SimpleNamespace(stats=dict(stats, substeps=1120), sim_seconds=4.8,
                                       time=12.0), 3.0)
    assert "1120 steps, 10 pair" in capsys.readouterr().err
