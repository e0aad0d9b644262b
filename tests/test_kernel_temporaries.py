"""No vector crosses from a kernel's top level into its loops through Taichi's global
temporaries.

A value a kernel computes at its top level and reads in a later loop (a separate task)
is kept in a global buffer. Taichi 1.7 aligns scalars there but not vectors
(taichi/transforms/offload.cpp, ``allocate_global``), so a vec3 of f64 can land at a
4-byte offset: the CPU reads it, CUDA stops with CUDA_ERROR_MISALIGNED_ADDRESS (the
10^5-sphere silo did). The CPU cannot show the fault, but Taichi's IR shows the buffer's
types: this test compiles the kernels of a scene with every granular feature, every
loop parallel, and asserts that no global temporary is a vector (docs/backends.md).
"""
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def test_no_vector_is_kept_in_global_temporaries():
    env = dict(os.environ, TAICHI_SPHERES_COMPILE="fast")
    proc = subprocess.Popen([sys.executable, os.path.join(HERE, "kernel_temporaries.py")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=HERE)
    temporaries, vectors = 0, []
    for line in proc.stdout:
        if "global tmp var" in line:
            temporaries += 1
            if "Tensor" in line:
                vectors.append(line.strip())
    err = proc.stderr.read()
    assert proc.wait() == 0, err[-2000:]
    assert temporaries > 0, "no IR was printed: the check saw nothing"
    assert not vectors, (f"{len(vectors)} vector global temporaries, e.g. {vectors[:3]}: "
                         "compute such a vector inside the loop that reads it")
