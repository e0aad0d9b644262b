#!/usr/bin/env python3
"""Digest of the same-bits reference scene after a fixed run, by code path.

The engine promises: same scene, precision and thread count -> same bits, on every
CPU, in both compile modes, fused or kernel by kernel, with serial or parallel
colour launches. This script runs ``builders.same_bits_scene(n)`` for each case of
``tests/same_bits.json`` ("small": 400 spheres for 0.8 s, ~1,000 steps, piling up on
the floor; "large": 3,000 spheres, where detection keeps near lists and sweeps can
launch per colour; "frictional": the small case with friction, spin and a post of
static geometry; "materials": the frictional case with every other sphere of a
second material; "plain": the small case with plain Gauss-Seidel sweeps at 100 / 100,
the full caps in every step and no substeps, the contact solver's former defaults;
"equal": the small case with equal radii and masses, the contact solver's equal-mass
row updates and packed rows)
and prints the digest of the final positions and velocities (``observe.state_digest``)
with the collision counts, for each path asked for, and whether it matches the digest
stored there (``tests/test_same_bits.py`` holds the engine to it).

    python tools/state_digest.py                          # both cases, f64 and f32
    python tools/state_digest.py --paths default fused parallel --compile optimized
    python tools/state_digest.py --write                  # store new digests (after an
                                                          # intended change of physics)

Run it on another machine (another CPU model, ARM) to check the promise there: every
line must say ``match``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
STORED = os.path.join(ROOT, "tests", "same_bits.json")
PATHS = ("default", "fused", "parallel")
CASES = ["small", "large", "frictional", "materials", "plain", "equal"]


def load_stored() -> dict:
    with open(STORED) as f:
        return json.load(f)


def run_path(case: dict, precision: str, path: str, threads=None, compile=None) -> dict:
    """Run the reference scene of ``case`` (n, duration) along one code path; the
    digest and counts. path: 'default' (kernel by kernel, what the CPU picks), 'fused'
    (the fused step, below 3,000 spheres), 'parallel' (every sweep as one parallel
    launch per colour, as on a GPU: from 3,000 spheres on)."""
    sys.path.insert(0, ROOT)
    import taichi_spheres as ts
    from taichi_spheres import runtime
    from taichi_spheres.builders import same_bits_case_scene
    from taichi_spheres.config import DEFAULT
    runtime.ensure("cpu", precision, threads=threads, compile=compile)
    tuning = DEFAULT.with_(few_pairs=-1, serial_resolve_pairs=-1) if path == "parallel" \
        else DEFAULT
    tuning = tuning.with_(**case.get("tuning", {}))
    sim = ts.Simulation(same_bits_case_scene(case),
                        precision=precision, threads=threads,
                        fused=path == "fused", tuning=tuning)
    sim.advance(case["duration"])
    s = sim.stats
    return dict(precision=precision, path=path, compile=sim.runtime.compile,
                digest=ts.observe.state_digest(sim.state(), precision), steps=s["steps"],
                pair_collisions=s["pair_collisions"], wall_collisions=s["wall_collisions"])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", nargs="+", default=CASES, choices=CASES)
    p.add_argument("--precisions", nargs="+", default=["f64", "f32"], choices=["f64", "f32"])
    p.add_argument("--paths", nargs="+", default=["default"], choices=PATHS)
    p.add_argument("--compile", default=None, choices=["fast", "optimized"])
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--write", action="store_true",
                   help="store the default path's digests in tests/same_bits.json")
    args = p.parse_args(argv)
    stored = load_stored()
    print(f"# {platform.machine()} {platform.processor() or ''} {platform.platform()}")
    ok = True
    for name in args.cases:
        case = stored[name]
        for precision in args.precisions:
            for path in args.paths:
                row = dict(case=name, **run_path(case, precision, path, args.threads,
                                                 args.compile))
                row["match"] = row["digest"] == case["digests"].get(precision)
                ok &= row["match"]
                print(json.dumps(row), flush=True)
                if args.write and path == "default":
                    case["digests"][precision] = row["digest"]
    if args.write:
        with open(STORED, "w") as f:
            json.dump(stored, f, indent=2)
            f.write("\n")
        print(f"wrote {STORED}")
        return 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
