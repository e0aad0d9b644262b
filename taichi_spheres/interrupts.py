"""Ctrl-C without losing what was written (used by the output and checkpoint stages).

imageio-ffmpeg kills the encoder when KeyboardInterrupt lands inside a frame write (it
treats any BaseException there as "do not wait for ffmpeg"), which leaves an mp4 without
its index that no player opens; a CSV row or a checkpoint cut in half is as bad. Such
writes run inside :func:`hold_interrupts`.
"""
from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["hold_interrupts"]


@contextlib.contextmanager
def hold_interrupts():
    """Hold Ctrl-C (SIGINT) until the block ends, then deliver it to the previous handler
    (KeyboardInterrupt right after the block, by default).

    A second Ctrl-C inside the block is delivered at once (the user insists: a stalled
    write can still be aborted). Nested blocks deliver once, at the end of the outermost.
    If the block raises, a held Ctrl-C is dropped: the exception already stops the work.
    Outside the main thread (where Python cannot set handlers) or under a handler
    installed from C, the block runs unguarded.
    """
    main = threading.current_thread() is threading.main_thread()
    current = signal.getsignal(signal.SIGINT) if main else None
    if current is None or getattr(current, "holds_interrupts", False):
        yield       # not the main thread, a handler set from C, or held by an outer block
        return
    caught = []

    def hold(signum, frame):
        caught.append(signum)
        if len(caught) > 1:
            signal.signal(signal.SIGINT, previous)
            signal.raise_signal(signal.SIGINT)

    hold.holds_interrupts = True
    previous = signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        signal.raise_signal(signal.SIGINT)
