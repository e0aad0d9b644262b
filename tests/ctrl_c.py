"""Interrupting a command-line subprocess with a real Ctrl-C (SIGINT)."""
import signal
import subprocess
import sys
import time


def default_sigint():
    """In the child before exec: SIGINT to its default, so that the CLI's Python gets
    its own Ctrl-C handler even where the test runner was started with SIGINT ignored
    (a shell starts background jobs so, and children inherit it)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_cli(args, cwd, **popen):
    """``python -m taichi_spheres.cli ARGS`` in ``cwd``, Ctrl-C-able (default_sigint)."""
    return subprocess.Popen([sys.executable, "-m", "taichi_spheres.cli", *args], cwd=cwd,
                            preexec_fn=default_sigint, **popen)


def interrupt_after_lines(args, cwd, path, lines, timeout=300):
    """Start ``python -m taichi_spheres.cli ARGS`` in ``cwd``, send SIGINT once the file
    ``path`` has more than ``lines`` lines (or after ``timeout`` s), and return
    (exit code, stderr)."""
    proc = start_cli(args, cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + timeout
    while time.time() < deadline:
        if path.exists() and len(path.read_text().splitlines()) > lines:
            break
        time.sleep(0.05)
    _, err = interrupt(proc)
    return proc.returncode, err


def interrupt(proc, timeout=120):
    """Send ``proc`` SIGINT and wait for it to end (``communicate``: its output); if it
    has not ended within ``timeout`` s, kill it (no run is left behind) and raise
    subprocess.TimeoutExpired."""
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
