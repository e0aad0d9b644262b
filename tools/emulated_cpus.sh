#!/usr/bin/env bash
# Same bits on other x86-64 CPU models: run tools/state_digest.py under QEMU user-mode
# emulation of each model given (default: Nehalem SandyBridge Haswell-noTSX EPYC-Rome),
# each with a fresh Taichi kernel cache, so that LLVM compiles for the emulated CPU
# (it reads the model from cpuid, which QEMU emulates). Every row must say "match".
# QEMU 7.2 emulates SSE4.2, AVX, AVX2 and FMA but not AVX-512 (run the script natively
# on such a CPU). Emulation is slow: 1-10 min per model for the "small" case. A model
# whose run prints no digest line crashed: its stderr is hidden, rerun that command
# by hand with `-X faulthandler` to see where.
#
#   bash tools/emulated_cpus.sh                       # installs qemu-user with apt-get
#   bash tools/emulated_cpus.sh Nehalem Haswell-noTSX
#   CASES="small frictional" PRECISIONS=f64 bash tools/emulated_cpus.sh   # other cases
set -euo pipefail
cd "$(dirname "$0")/.."
command -v qemu-x86_64 >/dev/null || { apt-get update -qq && apt-get install -y -qq qemu-user; }
venv_python=.venv/bin/python
real_python=$(readlink -f "$venv_python")
models=("$@")
[ ${#models[@]} -gt 0 ] || models=(Nehalem SandyBridge Haswell-noTSX EPYC-Rome)
for cpu in native "${models[@]}"; do
  cache=$(mktemp -d)
  start=$(date +%s)
  if [ "$cpu" = native ]; then
    run=("$venv_python")
  else
    # -0: the interpreter sees the venv's path as argv[0] and finds its packages
    run=(qemu-x86_64 -cpu "$cpu" -0 "$venv_python" "$real_python")
  fi
  # numpy's OpenBLAS picks its kernels from cpuid and, under QEMU, picked ones with
  # instructions Nehalem and Sandy Bridge lack (SIGILL in a matrix product): name the core
  case "$cpu" in
    Nehalem) export OPENBLAS_CORETYPE=Nehalem ;;
    SandyBridge) export OPENBLAS_CORETYPE=Sandybridge ;;
    *) unset OPENBLAS_CORETYPE ;;
  esac
  echo "## $cpu"
  TAICHI_SPHERES_COMPILE=fast TI_OFFLINE_CACHE_FILE_PATH=$cache \
    "${run[@]}" tools/state_digest.py --cases ${CASES:-small} --precisions ${PRECISIONS:-f64 f32} 2>/dev/null | grep '^{' || true
  echo "# $cpu: $(( $(date +%s) - start )) s"
  rm -rf "$cache"
done
