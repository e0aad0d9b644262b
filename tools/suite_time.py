#!/usr/bin/env python3
"""Wall time of the test suite (``make test``) as CI runs it: an empty Taichi kernel
cache, the CPU backend, the Makefile's workers. Prints pytest's summary line and the
time; with ``--write`` puts them into docs/bench.md (its own section).

    python tools/suite_time.py            # one run of make test (docs/bench.md "Test suite": its time)
    python tools/suite_time.py --write
    python tools/suite_time.py --census   # and count the engines the tests compile

With ``--census`` each worker logs every engine the tests build (tools/
engine_census_plugin.py), and the report says how many, of how many kinds, how many
were built again in one worker (after Taichi was initialised again, or for more room)
and which test files built most: most of the suite's time is compiling them.
"""
from __future__ import annotations

import argparse
import collections
import datetime
import json
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
from engine_census_plugin import CENSUS_ENV  # noqa: E402


def run_suite(**extra: str) -> tuple:
    """(pytest's summary line, wall seconds, exit code) of ``make test`` with the
    environment variables ``extra`` set too; pytest's FAILED and ERROR lines go to
    stderr."""
    with tempfile.TemporaryDirectory() as cache:
        env = kernel_cache_env(cache, **extra)
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


def census_env(log_dir: str) -> dict:
    """The environment variables that load tools/engine_census_plugin.py into make
    test's pytest workers, logging into ``log_dir``."""
    path = os.pathsep.join(p for p in (HERE, os.environ.get("PYTHONPATH", "")) if p)
    opts = " ".join(o for o in (os.environ.get("PYTEST_ADDOPTS", ""), "-p engine_census_plugin")
                    if o)
    return {"PYTHONPATH": path, "PYTEST_ADDOPTS": opts, CENSUS_ENV: log_dir}


def census(log_dir: str) -> str:
    """The report on the engines logged in ``log_dir`` (one .jsonl file per worker)."""
    per_worker = {}
    for name in sorted(n for n in os.listdir(log_dir) if n.endswith(".jsonl")):
        with open(os.path.join(log_dir, name), encoding="utf-8") as src:
            per_worker[name[:-len(".jsonl")]] = [json.loads(line) for line in src]
    rows = [row for worker in per_worker.values() for row in worker]
    kinds = {row["kind"] for row in rows}
    again = sum(len(worker) - len({row["kind"] for row in worker})
                for worker in per_worker.values())
    files = collections.Counter(row["test"].split("::")[0] for row in rows)
    top = ", ".join(f"{name} {count}" for name, count in files.most_common(8))
    shared = len(rows) - again - len(kinds)
    return (f"Engines built (`--census`): {len(rows)} in {len(per_worker)} workers "
            f"({', '.join(str(len(w)) for w in per_worker.values())}), {len(kinds)} kinds; "
            f"{again} of them a kind their worker had built before (Taichi initialised "
            f"again, or more room), {shared} a kind another worker built too. Most by "
            f"test file: {top}.\n" + kernel_census(log_dir))


def kernel_census(log_dir: str, top: int = 12) -> str:
    """The kernels whose compiles took the most seconds over the workers
    (``<worker>.kernels.json`` of tools/engine_census_plugin.py), as a table."""
    totals = collections.defaultdict(lambda: [0.0, 0.0, 0])
    for name in os.listdir(log_dir):
        if name.endswith(".kernels.json"):
            with open(os.path.join(log_dir, name), encoding="utf-8") as src:
                for kernel, row in json.load(src).items():
                    totals[kernel] = [a + b for a, b in zip(totals[kernel], row)]
    if not totals:
        return ""
    whole = sum(a + b for a, b, _ in totals.values())
    rows = sorted(totals.items(), key=lambda item: -(item[1][0] + item[1][1]))[:top]
    lines = [f"\nKernel compiles over the workers: {whole:.0f} s in all (the AST pass, and "
             "each compiled instance's first launch: LLVM's compile and one run); the "
             f"{top} kernels that took the most:\n",
             "| kernel | instances | AST pass [s] | first launches [s] | share |",
             "|---|---|---|---|---|"]
    lines += [f"| {name} | {n} | {ast:.0f} | {first:.0f} | {(ast + first) / whole:.0%} |"
              for name, (ast, first, n) in rows]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--write", action="store_true", help="write the result into docs/bench.md")
    p.add_argument("--census", action="store_true",
                   help="also count the engines the tests build (tools/engine_census_plugin.py)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as log_dir:
        summary, seconds, code = run_suite(**(census_env(log_dir) if args.census else {}))
        counted = census(log_dir) if args.census else ""
    text = f"""## Test suite

Generated {datetime.date.today().isoformat()} by `python tools/suite_time.py{' --census' if args.census else ''}{' --write' if args.write else ''}` on {cpu_name()}, {os.cpu_count()} cores, Python {platform.python_version()}:
`make test` (CPU backend, the Makefile's pytest-xdist workers, fast compile mode) with an
empty Taichi kernel cache, as CI runs it: **{seconds / 60:.1f} min** ({seconds:.0f} s),
{summary}.
"""
    if counted:
        text += "\n" + counted
    publish(text, "test-suite", args.write and code == 0)
    return code


if __name__ == "__main__":
    sys.exit(main())
