"""Output stage without Taichi kernels: Ctrl-C never costs the frames already written."""
import os
import signal
import threading
import time

import numpy as np
import pytest

from taichi_spheres import checkpoint
from taichi_spheres.interrupts import hold_interrupts
from taichi_spheres.output import VideoWriter


@pytest.fixture(autouse=True)
def default_ctrl_c():
    """Python's own SIGINT handler, whatever the test runner was started with."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_ctrl_c_is_held_until_the_block_ends():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with hold_interrupts():
            signal.raise_signal(signal.SIGINT)
            done.append("after the signal")
    assert done == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_ctrl_c_aborts_at_once():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with hold_interrupts():
            signal.raise_signal(signal.SIGINT)
            done.append("held")
            signal.raise_signal(signal.SIGINT)
            done.append("never")
    assert done == ["held"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_nested_blocks_deliver_one_interrupt_at_the_outer_end():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with hold_interrupts():
            with hold_interrupts():
                signal.raise_signal(signal.SIGINT)
            done.append("inner ended")
        done.append("never")
    assert done == ["inner ended"]


def test_ignored_ctrl_c_stays_ignored_and_no_signal_no_interrupt():
    with hold_interrupts():
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with hold_interrupts():
        signal.raise_signal(signal.SIGINT)
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_other_threads_run_unguarded():
    def in_thread():          # signal.signal would raise ValueError outside the main thread
        with hold_interrupts():
            seen.append("ran")
    seen = []
    t = threading.Thread(target=in_thread)
    t.start()
    t.join()
    assert seen == ["ran"]


def _ffmpeg_or_skip():
    """Skip where imageio-ffmpeg finds no ffmpeg to run (its platform wheel ships one;
    IMAGEIO_FFMPEG_EXE names another), or where imageio-ffmpeg is not installed: the only
    mp4 test not behind the Vulkan check."""
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    try:
        imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:
        pytest.skip(f"no ffmpeg here: {exc}")


def test_ctrl_c_during_frame_writes_leaves_a_playable_video(tmp_path):
    """imageio-ffmpeg kills the encoder when KeyboardInterrupt lands inside a write (an mp4
    without index: unreadable). Large random frames keep the writer blocked on ffmpeg's pipe,
    where an unguarded signal lands; every frame written before Ctrl-C must be readable."""
    import imageio.v2 as imageio
    _ffmpeg_or_skip()
    path = str(tmp_path / "v.mp4")
    video = VideoWriter(path, 30)
    frame = np.random.default_rng(0).integers(0, 255, (720, 1280, 3), dtype=np.uint8)
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    deadline = time.monotonic() + 120
    try:
        with pytest.raises(KeyboardInterrupt):
            while time.monotonic() < deadline:
                video.write(frame)
                if video.frames == 2:      # ffmpeg is running: interrupt in 0.5 s
                    timer.start()
    finally:
        timer.cancel()
        video.close()
    assert video.frames >= 2
    assert imageio.get_reader(path).count_frames() == video.frames


def test_resume_after_an_interrupted_prefix_copy_keeps_the_earlier_video(tmp_path):
    """--resume sets the earlier video aside and copies its first frames into a new one;
    interrupted there, the next --resume must start from the set-aside file again (not
    from the partial copy)."""
    video = tmp_path / "run.mp4"
    video.write_text("earlier video")
    old = checkpoint.set_aside(str(video))
    assert open(old).read() == "earlier video" and not video.exists()
    video.write_text("partial copy")         # the copy was interrupted
    assert checkpoint.set_aside(str(video)) == old
    assert open(old).read() == "earlier video" and not video.exists()
    assert checkpoint.set_aside(str(tmp_path / "none.mp4")) is None
