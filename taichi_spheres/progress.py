"""Progress of a ``taichi-spheres run`` on stderr.

A progress bar redrawn as frames are done (unless --quiet), and status lines that a run
prints on its own whenever it printed nothing for ``--status-every`` seconds (default
STATUS_EVERY; also with --quiet, also in the middle of a long frame) or at once when it
receives SIGUSR1 (``kill -USR1 PID``, as ``dd`` does) or SIGINFO (Ctrl-T, on BSD and
macOS).
"""
from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time

__all__ = ["Progress", "status_reports", "STATUS_EVERY", "STATUS_SIGNALS"]

#: Default of --status-every [s]: a run prints a status line when it printed none for
#: this long.
STATUS_EVERY = 60.0
#: Signals that print a status line at once, where the system has them.
STATUS_SIGNALS = ("SIGUSR1", "SIGINFO")
#: A terminal's progress bar is redrawn at most this often [s].
BAR_REDRAW = 0.2
#: Width of the progress bar [characters].
BAR_WIDTH = 24


class Progress:
    """Progress bar and status lines of one run of ``duration`` [s] in ``frames`` frames.

    ``steps`` is the estimated step count (None: unknown); :meth:`attach` gives it the
    Simulation once built (status lines before that say the run is setting up)."""

    def __init__(self, duration, frames, quiet=False, status_every=STATUS_EVERY, steps=None):
        self.duration, self.frames, self.quiet = duration, frames, quiet
        self.status_every, self.steps = status_every, steps
        self.tty = sys.stderr.isatty()
        self.t0 = self.last_line = time.perf_counter()
        self.sim, self.frame = None, -1
        self._start_time, self._last_tenth = 0.0, -1
        self._open_line = False       # a bar was drawn without its newline
        self._lock = threading.RLock()

    def attach(self, sim):
        """Report on ``sim`` from its current time on (a resumed run starts later)."""
        self.sim, self._start_time = sim, sim.time

    def frame_done(self, frame, final=False):
        """Frame ``frame`` (0-based) is written: redraw the bar, or a status line when due."""
        self.frame = frame
        now = time.perf_counter()
        if self.quiet:
            if not final:
                self.status_if_due()
            return
        tenth = int(self._done() * 10)
        if not final and (self.tty and now - self.last_line < BAR_REDRAW or
                          not self.tty and tenth == self._last_tenth):
            return
        self._last_tenth = tenth
        self._emit(self._bar() + "  " + self._fields(), newline=final or not self.tty)

    def status_if_due(self):
        """Print a status line if none was printed for status_every seconds."""
        with self._lock:
            if time.perf_counter() - self.last_line >= self.status_every:
                self.status()

    def status(self):
        """Print a status line now (own line, also with --quiet)."""
        if self.sim is None:
            text = f"setting up (compiling kernels), {time.perf_counter() - self.t0:.0f} s"
        else:
            text = f"frame {self.frame + 1}/{self.frames}  " + self._fields()
        self._emit("status: " + text, newline=True, own_line=True)

    def _done(self):
        if self.sim is None:
            return 0.0
        span = self.duration - self._start_time
        return 1.0 if span <= 0 else min(1.0, (self.sim.time - self._start_time) / span)

    def _bar(self):
        return f"[{'#' * int(BAR_WIDTH * self._done()):<{BAR_WIDTH}}]"

    def _fields(self):
        st = self.sim.stats
        elapsed = time.perf_counter() - self.t0
        done = self._done()
        eta = f"{elapsed / done * (1 - done):5.1f} s" if done > 0 else "unknown"
        steps = f"{st['steps']}" + (f" of ~{self.steps:.1e}" if self.steps else "")
        return (f"t={self.sim.time:.3f}/{self.duration:g} s  steps={steps}  "
                f"collisions={st['pair_collisions']}+{st['wall_collisions']} wall  "
                f"elapsed {elapsed:.0f} s  ETA {eta}")

    def _emit(self, text, newline, own_line=False):
        with self._lock:
            lead = "\n" if own_line and self._open_line else ("\r" if self.tty and not own_line
                                                              else "")
            print(lead + text, end="\n" if newline else "", file=sys.stderr, flush=True)
            self._open_line = not newline
            self.last_line = time.perf_counter()


@contextlib.contextmanager
def status_reports(progress: Progress):
    """While the block runs: a status line on STATUS_SIGNALS, and one whenever
    ``progress`` printed none for its status_every seconds (from a watcher thread, so
    that a frame that takes hours still reports)."""
    stop = threading.Event()

    def watch():
        while not stop.wait(max(0.05, progress.status_every -
                                (time.perf_counter() - progress.last_line))):
            progress.status_if_due()

    watcher = threading.Thread(target=watch, name="taichi-spheres status", daemon=True)
    previous = _install_signal_handlers(lambda signum, frame: progress.status())
    watcher.start()
    try:
        yield progress
    finally:
        stop.set()
        watcher.join()
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _install_signal_handlers(handler) -> dict:
    """Install ``handler`` for STATUS_SIGNALS the system has (main thread only); returns
    the handlers it replaced."""
    previous = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    for name in STATUS_SIGNALS:
        signum = getattr(signal, name, None)
        if signum is not None:
            previous[signum] = signal.signal(signum, handler)
    return previous
