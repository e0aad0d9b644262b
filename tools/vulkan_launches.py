#!/usr/bin/env python3
"""How many kernel launches one process survives on arch=vulkan.

Launches a small kernel (one parallel loop over a few fields, returning an i32, as the
engine's detection and sweep kernels do) up to --launches times and prints a line
every --every launches. Under Taichi 1.7.4, Mesa 25's lavapipe crashes the process
(segfault in vkAllocateDescriptorSets) after some tens of thousands of launches;
Debian 12's lavapipe (Mesa 22.3) does not. The last line printed says how far it got. Run it with
the driver to test in VK_ICD_FILENAMES, e.g. after tools/vulkan_cpu_suite.sh fetched
Mesa 25:

    VK_ICD_FILENAMES=$PWD/.cache/mesa25/lvp_icd.json \\
    LD_LIBRARY_PATH=$PWD/.cache/mesa25/root/usr/lib/x86_64-linux-gnu \\
    python tools/vulkan_launches.py
"""
import argparse
import faulthandler
import time

import taichi as ti


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--launches", type=int, default=200_000)
    ap.add_argument("--every", type=int, default=5_000)
    ap.add_argument("--fields", type=int, default=20, help="fields the kernel binds")
    args = ap.parse_args()
    faulthandler.enable()
    ti.init(arch=ti.vulkan, log_level=ti.WARN)
    fields = [ti.field(ti.i32, shape=100) for _ in range(args.fields)]

    @ti.kernel
    def bump() -> ti.i32:
        for i in range(100):
            for f in ti.static(fields):
                f[i] += 1
        return fields[0][3]

    t0 = time.perf_counter()
    for k in range(1, args.launches + 1):
        bump()
        if k % args.every == 0:
            print(f"{k} launches, {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"survived {args.launches} launches")


if __name__ == "__main__":
    main()
