"""Interrupting a command-line subprocess with a real Ctrl-C (SIGINT)."""
import signal
import subprocess
import sys
import time


def interrupt_after_lines(args, cwd, path, lines, timeout=300):
    """Start ``python -m taichi_spheres.cli ARGS`` in ``cwd``, send SIGINT once the file
    ``path`` has more than ``lines`` lines (or after ``timeout`` s), and return
    (exit code, stderr)."""
    proc = subprocess.Popen([sys.executable, "-m", "taichi_spheres.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + timeout
    while time.time() < deadline:
        if path.exists() and len(path.read_text().splitlines()) > lines:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err
