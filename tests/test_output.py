"""Output stage without Taichi kernels: Ctrl-C never costs the frames already written."""
import os
import signal
import threading

import numpy as np
import pytest

from taichi_spheres.checkpoint import hold_interrupts
from taichi_spheres.output import VideoWriter


def test_ctrl_c_is_held_until_the_block_ends():
    before = signal.getsignal(signal.SIGINT)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with hold_interrupts():
            signal.raise_signal(signal.SIGINT)
            done.append("after the signal")
    assert done == ["after the signal"]
    assert signal.getsignal(signal.SIGINT) is before


def test_nested_blocks_deliver_one_interrupt_at_the_outer_end():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with hold_interrupts():
            with hold_interrupts():
                signal.raise_signal(signal.SIGINT)
            done.append("inner ended")
        done.append("never")
    assert done == ["inner ended"]


def test_no_signal_no_interrupt_and_other_threads_run_unguarded():
    before = signal.getsignal(signal.SIGINT)
    with hold_interrupts():
        pass
    assert signal.getsignal(signal.SIGINT) is before

    def in_thread():          # signal.signal would raise ValueError outside the main thread
        with hold_interrupts():
            seen.append("ran")
    seen = []
    t = threading.Thread(target=in_thread)
    t.start()
    t.join()
    assert seen == ["ran"]


def test_ctrl_c_during_frame_writes_leaves_a_playable_video(tmp_path):
    """imageio-ffmpeg kills the encoder when KeyboardInterrupt lands inside a write (an mp4
    without index: unreadable). Large random frames keep the writer blocked on ffmpeg's pipe,
    where an unguarded signal lands; every frame written before Ctrl-C must be readable."""
    import imageio.v2 as imageio
    path = str(tmp_path / "v.mp4")
    video = VideoWriter(path, 30)
    frame = np.random.default_rng(0).integers(0, 255, (720, 1280, 3), dtype=np.uint8)
    timer = threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            for _ in range(10_000):
                video.write(frame)
    finally:
        timer.cancel()
        video.close()
    assert video.frames >= 2
    assert imageio.get_reader(path).count_frames() == video.frames

