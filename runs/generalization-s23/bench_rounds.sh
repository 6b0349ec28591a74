#!/bin/bash
# session 23: the held-out 1080p frame, code of the session's start (/work/wt_old at 293c311) and of now, in three
# interleaved rounds (this VM's timings moved by up to 25% between single runs), v6 on both, nothing else running
cd /work/data
. /work/main/.venv/bin/activate
F=/work/data/heldout_g1_s5/scene_0005/deepz/noisy_spp16.0000.exr
M="--model cpu-small-pdl-gza-v6"
for r in 1 2 3; do
    ( cd /work/wt_old && env -u NUMPY_MADVISE_HUGEPAGE PYTHONPATH=/work/wt_old python bench/denoise.py --real "" \
        --frame $F $M ) > s23/bench_r${r}_before.log 2>&1
    ( cd /work/main && python bench/denoise.py --real "" --frame $F $M ) > s23/bench_r${r}_after.log 2>&1
done
echo done > s23/bench_rounds.done
