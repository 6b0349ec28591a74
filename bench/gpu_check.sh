#!/usr/bin/env bash
# The GPU path, checked and timed on a machine with a CUDA GPU: builds the CUDA RaNA kernels (and the CPU ones the
# comparisons need), runs the GPU tests (tests/test_rana_cuda.py: kernels against the reference;
# tests/test_gpu.py: shipped models, AOV reuse and the flat prior on the GPU against the CPU; `--device cuda`), then
# bench/rana.py (CUDA against this machine's CPU kernels; then the staged CUDA kernels against the one-thread ones)
# and bench/denoise.py on a 1080p frame with `--device cuda` (flat OIDN on the same GPU in the same run). Each step
# has a time limit, so that one that hangs does not hide the rest. Needs the package's dependencies importable.
# Usage: bench/gpu_check.sh [FRAME.exr] [LOGDIR]   (FRAME: the deep frame bench/denoise.py tiles to 1080p)
# TORCH_CUDA_ARCH_LIST (default: the GPU present) and TORCH_EXTENSIONS_DIR/RANAD_KERNEL_CACHE are honoured.
set -uo pipefail
cd "$(dirname "$0")/.."
FRAME=${1:-}
LOG=${2:-$(mktemp -d)}
mkdir -p "$LOG"
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
THREADS=$(nproc)
python3 -c "import torch; print('torch', torch.__version__, 'GPU:', torch.cuda.get_device_name())" || exit 1
t0=$(date +%s)
python3 -c "from ranad_core.rana.extension import load_cuda_extension as b; b()" > "$LOG/build_cuda.log" 2>&1 &
cuda_pid=$!
python3 -c "from ranad_core.rana.extension import load_cpu_extension as b; b()" > "$LOG/build_cpu.log" 2>&1 &
cpu_pid=$!
wait $cuda_pid; cuda_rc=$?; wait $cpu_pid; cpu_rc=$?
echo "builds: CUDA rc $cuda_rc, CPU rc $cpu_rc, $(( $(date +%s) - t0 )) s"
grep -i "error\|spill" "$LOG/build_cuda.log" | head -20
[ $cuda_rc -eq 0 ] || { tail -30 "$LOG/build_cuda.log"; exit 1; }
timeout 300 python3 -m pytest -q -rs -p no:cacheprovider tests/test_rana_cuda.py tests/test_gpu.py 2>&1 \
  | tee "$LOG/tests.log" | tail -25
timeout 120 python3 bench/rana.py --threads "$THREADS" --repeats 5 2>&1 | tee "$LOG/bench_rana.log"
timeout 120 python3 bench/rana.py --device cuda --repeats 5 --chunks 16,32,64 2>&1 | tee "$LOG/bench_rana_cuda.log"
if [ -n "$FRAME" ]; then
  timeout 240 python3 bench/denoise.py --device cuda --threads "$THREADS" --real '' --frame "$FRAME" \
    --args=--profile 2>&1 | tee "$LOG/bench_denoise_cuda.log"
fi
