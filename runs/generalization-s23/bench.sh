#!/bin/bash
# session 23, issue 27's figures with nothing else running: the held-out 1080p frame with the code of the session's
# start (293c311, a worktree at /work/wt_old) and of now, v6 on both, then the project's synth frame (now only);
# after the model runs (chain8.done)
cd /work/data
. /work/main/.venv/bin/activate
while [ ! -f s23/chain8.done ]; do sleep 10; done
F=/work/data/heldout_g1_s5/scene_0005/deepz/noisy_spp16.0000.exr
M="--model cpu-small-pdl-gza-v6"
( cd /work/wt_old && env -u NUMPY_MADVISE_HUGEPAGE PYTHONPATH=/work/wt_old python bench/denoise.py --real "" \
    --frame $F $M ) > s23/bench_before.log 2>&1
( cd /work/main && python bench/denoise.py --real "" --frame $F $M --args=--profile --args="--max-memory 4G" ) \
    > s23/bench_after.log 2>&1
( cd /work/main && python bench/denoise.py --real "" $M ) > s23/bench_synth.log 2>&1
echo done > s23/bench.done
