#!/usr/bin/env python3
"""Wall time of the test suite (``make test``) as CI runs it: an empty Taichi kernel
cache, the CPU backend, the Makefile's workers. Prints pytest's summary line and the
time; with ``--write`` puts them into docs/bench.md (its own section).

    python tools/suite_time.py            # one run of make test (docs/bench.md "Test suite": its time)
    python tools/suite_time.py --write
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
sys.path.insert(0, HERE)
from machine import cpu_name, kernel_cache_env, publish  # noqa: E402  (tools/machine.py)


def run_suite() -> tuple:
    """(pytest's summary line, wall seconds, exit code) of ``make test``; pytest's
    FAILED and ERROR lines go to stderr."""
    with tempfile.TemporaryDirectory() as cache:
        env = kernel_cache_env(cache)
        t0 = time.perf_counter()
        out = subprocess.run(["make", "test"], cwd=ROOT, env=env, capture_output=True,
                             text=True)
        seconds = time.perf_counter() - t0
    summary = [line for line in out.stdout.splitlines()
               if re.search(r"\d+ (passed|failed)", line)]
    for line in out.stdout.splitlines():
        if line.startswith(("FAILED", "ERROR")):
            print(line, file=sys.stderr)
    return (summary[-1].strip("= ") if summary else "no summary"), seconds, out.returncode


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--write", action="store_true", help="write the result into docs/bench.md")
    args = p.parse_args(argv)
    summary, seconds, code = run_suite()
    text = f"""## Test suite

Generated {datetime.date.today().isoformat()} by `python tools/suite_time.py{' --write' if args.write else ''}` on {cpu_name()}, {os.cpu_count()} cores, Python {platform.python_version()}:
`make test` (CPU backend, the Makefile's pytest-xdist workers, fast compile mode) with an
empty Taichi kernel cache, as CI runs it: **{seconds / 60:.1f} min** ({seconds:.0f} s),
{summary}.
"""
    publish(text, "test-suite", args.write and code == 0)
    return code


if __name__ == "__main__":
    sys.exit(main())
