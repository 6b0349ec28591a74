#!/usr/bin/env bash
# Compile-only check of the CUDA RaNA sources on a machine without a GPU (CI): the torch-free kernels with nvcc for
# each architecture (ptxas register spills reported), and the torch binding as plain C++ against the installed
# torch (no linking: a CPU build of torch has no CUDA libraries). Fails on any compile error.
set -euo pipefail
cd "$(dirname "$0")"
ARCHS=${RANAD_CUDA_ARCHS:-"80 86 89 90"}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
command -v nvcc >/dev/null || { echo "check_build: nvcc not found" >&2; exit 1; }
nvcc --version | tail -n 2
pids=()
for a in $ARCHS; do
  ( nvcc -std=c++20 -O3 --expt-relaxed-constexpr -gencode "arch=compute_$a,code=sm_$a" -Xptxas -warn-spills \
      -I. -c rana_cuda_kernels.cu -o "$OUT/rana_cuda_kernels_sm$a.o" > "$OUT/sm$a.log" 2>&1 \
    && echo "nvcc sm_$a: rana_cuda_kernels.cu OK ($(grep -c 'spilled' "$OUT/sm$a.log" || true) kernels with register spills)" \
    || { echo "nvcc sm_$a: FAILED"; cat "$OUT/sm$a.log"; exit 1; } ) &
  pids+=($!)
done
PY=${PYTHON:-python}
INC=$($PY -c "from torch.utils.cpp_extension import include_paths; import sysconfig; print(' '.join('-I' + p for p in include_paths() + [sysconfig.get_paths()['include']]))")
( g++ -std=c++20 -fsyntax-only -Wno-psabi $INC -I. -DTORCH_EXTENSION_NAME=ranad_rana_cuda rana_cuda.cpp \
  && echo "g++: rana_cuda.cpp (torch binding) OK" ) &
pids+=($!)
status=0
for p in "${pids[@]}"; do wait "$p" || status=1; done
if [ "$status" -ne 0 ]; then echo "check_build: FAILED" >&2; exit 1; fi
echo "check_build: CUDA sources compile for sm_${ARCHS// /, sm_}"
