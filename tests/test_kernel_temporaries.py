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
import threading

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))


def vector_temporaries(tmp_path, *args) -> list:
    """The vector-typed global temporaries in the IR of ``kernel_temporaries.py ARGS``."""
    env = dict(os.environ, TAICHI_SPHERES_COMPILE="fast")
    temporaries, vectors = 0, []
    with open(tmp_path / "stderr.txt", "w+") as err:     # a file: a full pipe would block
        proc = subprocess.Popen([sys.executable, os.path.join(HERE, "kernel_temporaries.py"),
                                 *args],
                                stdout=subprocess.PIPE, stderr=err, text=True, env=env,
                                cwd=HERE)
        watchdog = threading.Timer(600, proc.kill)      # a hung child fails the test
        watchdog.start()
        for line in proc.stdout:
            if "global tmp var" in line:
                temporaries += 1
                if "Tensor" in line:
                    vectors.append(line.strip())
        code = proc.wait()
        watchdog.cancel()
        err.seek(0)
        assert code == 0, err.read()[-2000:]
    assert temporaries > 0, "no IR was printed: the check saw nothing"
    return vectors


@pytest.mark.parametrize("args", [(), pytest.param(("no-substeps",), marks=pytest.mark.slow)],
                         ids=["default-rules", "no-substeps"])
def test_no_vector_is_kept_in_global_temporaries(tmp_path, args):
    vectors = vector_temporaries(tmp_path, *args)
    assert not vectors, (f"{len(vectors)} vector global temporaries, e.g. {vectors[:3]}: "
                         "compute such a vector inside the loop that reads it")
