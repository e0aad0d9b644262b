#!/bin/sh
# The GPU figures and the test suite on the CUDA backend, in one run, each part bounded
# in time so that one slow part leaves the others their turn:
#   bench  tools/bench.py --arch cuda (gas throughput, f64 and f32)     -> DIR/bench_cuda.md
#   beds   tools/contact_solver.py --beds-only --arch cuda (10^5 FCC bed) -> docs/bench.md
#   silo   tools/silo_large.py --arch cuda (10^5-sphere silo)           -> docs/bench.md
#   profile tools/kernel_profile.py --silo-large 100000 --arch cuda (where the 10^5 silo's
#          step goes, per kernel task)                                   -> docs/bench.md
#   suite  the suite (or SUITE_TESTS) with --arch cuda -> DIR/suite.log, failures as they happen in
#          DIR/failures.log
# Each part's log and a copy of docs/bench.md go to DIR; DIR/machine.txt says which parts
# ran, were skipped or failed (exit code 124: out of time). The script exits 1 if a part
# failed. The tools print each row as it is measured (in the logs), and write their
# reports at their end: a part that runs out of time leaves its rows in its log only.
# The suite compiles every test's kernels for the GPU, which takes most of its time:
# give it a run of its own (PARTS=suite SUITE_S=540) where time on the GPU is short.
#
#   sh tools/cuda_checks.sh [DIR]        # DIR defaults to out/cuda
#   PARTS="bench beds" sh tools/cuda_checks.sh out/cuda
# Environment: PARTS (default "bench beds silo profile suite"), PY (python, default python3),
# WORKERS (pytest-xdist workers, default 12), BED_SETTINGS (the beds' settings, default
# "defaults relaxed fast"), SUITE_TESTS (test files or node ids split at spaces, so no
# `-k "a or b"` and no paths with spaces; default all), BENCH_S,
# BEDS_S, SILO_S, PROFILE_S, SUITE_S (seconds each part may take).
set -u
mkdir -p "${1:-out/cuda}"
dir=$(cd "${1:-out/cuda}" && pwd)
cd "$(dirname "$0")/.." || exit 1
py=${PY:-python3}
parts=${PARTS:-bench beds silo profile suite}
failed=0
export PYTHONUNBUFFERED=1
{ date -u; nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv;
  "$py" -c "import taichi, numpy, sys; print(sys.version, taichi.__version__, numpy.__version__)"
  "$py" -c "import imageio_ffmpeg as f; print('ffmpeg', f.get_ffmpeg_exe())"
} >"$dir/machine.txt" 2>&1

# part NAME SECONDS LOG COMMAND...: run COMMAND for at most SECONDS if PARTS names NAME
part() {
  name=$1 limit=$2 log=$3
  shift 3
  case " $parts " in
    *" $name "*) ;;
    *) echo "$name skipped" >>"$dir/machine.txt"; return 0 ;;
  esac
  timeout "$limit" "$@" >"$dir/$log" 2>&1
  rc=$?
  echo "$name rc $rc" >>"$dir/machine.txt"
  [ "$rc" = 0 ] || failed=1
}

part bench "${BENCH_S:-240}" bench.log "$py" tools/bench.py --arch cuda \
    --sizes 10000 100000 1000000 --seconds 1.5 --feature-n 0 --out "$dir/bench_cuda.md"
part beds "${BEDS_S:-240}" beds.log "$py" tools/contact_solver.py --beds-only --arch cuda \
    --bed-settings ${BED_SETTINGS:-defaults relaxed fast} --child-timeout 70 --write
part silo "${SILO_S:-120}" silo.log "$py" tools/silo_large.py --arch cuda --duration 0.05 \
    --write
part profile "${PROFILE_S:-120}" profile.log "$py" tools/kernel_profile.py --silo-large 100000 \
    --arch cuda --window 0.01 --top 15 --write
cp docs/bench.md "$dir/bench.md"
export TAICHI_SPHERES_FAILURE_LOG="$dir/failures.log"
part suite "${SUITE_S:-200}" suite.log "$py" -m pytest -v --tb=short -n "${WORKERS:-12}" \
    --arch cuda -p no:cacheprovider ${SUITE_TESTS:-}
exit "$failed"
