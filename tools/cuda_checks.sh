#!/bin/sh
# The GPU figures and the test suite on the CUDA backend, in one run, each part bounded
# in time so that one slow part leaves the others their turn:
#   1. tools/bench.py --arch cuda (gas throughput, f64 and f32)      -> DIR/bench_cuda.md
#   2. tools/contact_solver.py --beds-only --arch cuda (10^5 FCC bed) -> docs/bench.md
#   3. tools/silo_large.py --arch cuda (10^5-sphere silo)            -> docs/bench.md
#   4. the suite with --arch cuda                                     -> DIR/suite.log
# Logs of each part and a copy of docs/bench.md go to DIR. The suite compiles every
# test's kernels for the GPU, which takes most of its time: give it a run of its own
# (PARTS=suite SUITE_S=540) where time on the GPU is short.
#
#   sh tools/cuda_checks.sh [DIR]        # DIR defaults to out/cuda
#   PARTS="bench beds" sh tools/cuda_checks.sh out/cuda
# Environment: PARTS (which parts, default "bench beds silo suite"), PY (python,
# default python3), WORKERS (pytest-xdist workers, default 12), BENCH_S, BEDS_S,
# SILO_S, SUITE_S (seconds each part may take).
set -u
dir=${1:-out/cuda}
py=${PY:-python3}
parts=${PARTS:-bench beds silo suite}
wants() { case " $parts " in *" $1 "*) return 0 ;; esac; return 1; }
mkdir -p "$dir"
export PYTHONUNBUFFERED=1
{ date -u; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv;
  $py -c "import taichi, numpy, sys; print(sys.version, taichi.__version__, numpy.__version__)"
} >"$dir/machine.txt" 2>&1

wants bench && timeout "${BENCH_S:-130}" $py tools/bench.py --arch cuda --sizes 10000 1000000 10000000 \
    --seconds 1.5 --feature-n 0 --out "$dir/bench_cuda.md" >"$dir/bench.log" 2>&1
echo "bench rc $? ($parts)" >>"$dir/machine.txt"

wants beds && timeout "${BEDS_S:-140}" $py tools/contact_solver.py --beds-only --arch cuda \
    --bed-settings defaults relaxed fast --child-timeout 60 --write >"$dir/beds.log" 2>&1
echo "beds rc $?" >>"$dir/machine.txt"

wants silo && timeout "${SILO_S:-80}" $py tools/silo_large.py --arch cuda --duration 0.05 --write \
    >"$dir/silo.log" 2>&1
echo "silo rc $?" >>"$dir/machine.txt"
cp docs/bench.md "$dir/bench.md"

wants suite && timeout "${SUITE_S:-200}" $py -m pytest -v --tb=short -n "${WORKERS:-12}" --arch cuda \
    -p no:cacheprovider >"$dir/suite.log" 2>&1
echo "suite rc $?" >>"$dir/machine.txt"
