"""Progress of a ``taichi-spheres run`` on stderr.

A tqdm progress bar in frames, with rate and ETA (unless --quiet; tqdm shows it only
when stderr is a terminal), and status lines that a run prints on its own whenever it
printed nothing for ``--status-every`` seconds (default STATUS_EVERY; also with --quiet,
also in the middle of a long frame) or at once when it receives SIGUSR1
(``kill -USR1 PID``, as ``dd`` does) or SIGINFO (Ctrl-T, on BSD and macOS).
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time

from tqdm import tqdm

__all__ = ["Progress", "status_reports", "STATUS_EVERY", "STATUS_SIGNALS"]

#: Default of --status-every [s]: a run prints a status line when it printed none for
#: this long.
STATUS_EVERY = 60.0
#: Signals that print a status line at once, where the system has them.
STATUS_SIGNALS = ("SIGUSR1", "SIGINFO")
#: The progress bar is redrawn at most this often [s].
BAR_REDRAW = 0.2
#: Bar width and screen height [characters, lines] where the terminal reports none.
FALLBACK_COLUMNS, FALLBACK_LINES = 100, 24


class Progress:
    """Progress bar and status lines of one run of ``duration`` [s] in ``frames`` frames.

    ``steps`` is the estimated step count (None: unknown); :meth:`attach` gives it the
    Simulation once built (status lines before that say the run is setting up) and
    opens the bar."""

    def __init__(self, duration, frames, quiet=False, status_every=STATUS_EVERY, steps=None):
        self.duration, self.frames, self.quiet = duration, frames, quiet
        self.status_every, self.steps = status_every, steps
        self.t0 = self.last_line = time.perf_counter()
        self.sim, self.frame = None, -1
        self.bar = None
        self._start_time = 0.0
        self._lock = threading.RLock()

    def attach(self, sim, first_frame=0):
        """Report on ``sim`` from its current time on (a resumed run starts later, at
        frame ``first_frame``)."""
        self.sim, self._start_time = sim, sim.time
        self.frame = first_frame - 1
        if not self.quiet:
            # disable=None: no bar unless stderr is a terminal (logs get status lines)
            self.bar = tqdm(total=self.frames, initial=first_frame, unit="frame",
                            file=sys.stderr, disable=None, mininterval=BAR_REDRAW,
                            leave=True, **_unknown_terminal_size())

    def frame_done(self, frame, final=False):
        """Frame ``frame`` (0-based) is written: advance the bar, or print a status line
        when one is due."""
        with self._lock:
            done, self.frame = frame - self.frame, frame
            if self.bar is not None and not self.bar.disable:
                st = self.sim.stats
                self.bar.set_postfix_str(
                    f"t={self.sim.time:.3f}/{self.duration:g} s, steps={st['steps']}, "
                    f"collisions={st['pair_collisions']}+{st['wall_collisions']} wall",
                    refresh=False)
                self.bar.update(done)
                self.last_line = time.perf_counter()
            elif not final:
                self.status_if_due()
            if final:
                self.close()

    def close(self):
        """Close the bar (its last state stays on the terminal); safe to call twice."""
        with self._lock:
            if self.bar is not None:
                self.bar.close()
                self.bar = None

    def status_if_due(self):
        """Print a status line if none was printed for status_every seconds."""
        with self._lock:
            if time.perf_counter() - self.last_line >= self.status_every:
                self.status()

    def status(self):
        """Print a status line now (own line above the bar, also with --quiet)."""
        if self.sim is None:
            text = f"setting up (compiling kernels), {time.perf_counter() - self.t0:.0f} s"
        else:
            text = f"frame {self.frame + 1}/{self.frames}  " + self._fields()
        with self._lock:
            tqdm.write("status: " + text, file=sys.stderr)
            sys.stderr.flush()
            self.last_line = time.perf_counter()

    def _done(self):
        """Fraction of the run's simulated time done (0 before attach)."""
        if self.sim is None:
            return 0.0
        span = self.duration - self._start_time
        return 1.0 if span <= 0 else min(1.0, (self.sim.time - self._start_time) / span)

    def _fields(self):
        st = self.sim.stats
        elapsed = time.perf_counter() - self.t0
        done = self._done()
        eta = f"{elapsed / done * (1 - done):5.1f} s" if done > 0 else "unknown"
        steps = f"{st['steps']}" + (f" of ~{self.steps:.1e}" if self.steps else "")
        return (f"t={self.sim.time:.3f}/{self.duration:g} s  steps={steps}  "
                f"collisions={st['pair_collisions']}+{st['wall_collisions']} wall  "
                f"elapsed {elapsed:.0f} s  ETA {eta}")


def _unknown_terminal_size() -> dict:
    """tqdm's ncols and nrows [characters, lines] for a terminal that reports a size of
    0 x 0 (some pseudo-terminals), where tqdm would hide the bar; {} otherwise (tqdm
    follows the terminal's width)."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError, AttributeError):
        return {}
    if size.columns and size.lines:
        return {"dynamic_ncols": True}
    return {"ncols": FALLBACK_COLUMNS, "nrows": FALLBACK_LINES}


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
        progress.close()
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
