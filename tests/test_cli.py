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
            "4", cwd=d)
    assert r.returncode == 0, r.stderr
    r = cli("run", "tiny.toml", "-o", "part.mp4", "--resume", "part.ckpt.npz", "--npz", cwd=d)
    assert r.returncode == 0, r.stderr
    full, part = read_csv(d / "full.csv"), read_csv(d / "part.csv")
    assert full == part
    np.testing.assert_array_equal(np.load(d / "full.npz")["x"][-1], np.load(d / "part.npz")["x"][-1])
    import imageio.v2 as imageio
    assert imageio.get_reader(str(d / "part.mp4")).count_frames() == 11


def test_resume_refuses_another_scene(tiny_run):
    d, _ = tiny_run
    (d / "other.toml").write_text(TINY.replace("speed = 1.0", "speed = 2.0"))
    r = cli("run", "other.toml", "-o", "other.mp4", "--resume", "full.ckpt.npz", cwd=d)
    assert r.returncode == 2 and "different scene" in r.stderr


def test_fused_run_writes_the_same_diagnostics(tiny_run):
    """--fused (one kernel per step on the CPU) changes the speed, not the numbers."""
    d, _ = tiny_run
    r = cli("run", "tiny.toml", "-o", "fused.mp4", "--no-video", "--fused", "--quiet", cwd=d)
    assert r.returncode == 0, r.stderr
    assert read_csv(d / "fused.csv") == read_csv(d / "full.csv")


def test_interrupt_keeps_a_playable_video(tmp_path, vulkan):
    import imageio.v2 as imageio
    (tmp_path / "tiny.toml").write_text(TINY.replace("duration = 0.5", "duration = 600.0"))
    proc = subprocess.Popen([sys.executable, "-m", "taichi_spheres.cli", "run", "tiny.toml",
                             "-o", "long.mp4", "--quiet"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    csv_path = tmp_path / "long.csv"
    deadline = time.time() + 300
    while time.time() < deadline:
        if csv_path.exists() and len(csv_path.read_text().splitlines()) > 5:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
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


def test_info_lists_compiled_features(tmp_path):
    root = os.path.join(os.path.dirname(__file__), "..")
    r = cli("info", os.path.join(root, "scenes", "gas.toml"), cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "spheres: 4096" in r.stdout
    assert "gravity: off (compiled out)" in r.stdout
    assert "MiB" in r.stdout


def test_cli_choices_match_the_runtime():
    """The CLI spells out the arches and compile modes (parsing must not import Taichi):
    they are the runtime's, plus "auto"."""
    from taichi_spheres import cli, runtime
    assert cli.ARCHS == runtime.ARCHS
    assert set(cli.COMPILE_CHOICES) == set(runtime.COMPILE_MODES) | {"auto"}
