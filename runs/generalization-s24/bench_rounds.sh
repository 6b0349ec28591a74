#!/bin/bash
# session 24: issue 27's two frames, the session's starting code (/work/wt_s24 at f3514c7) and now, interleaved (this
# VM's timings move by up to 25% between single runs), the default model on both, nothing else running.
# The held-out 1080p frame (bench/denoise.py --frame, heldout_g1_s5's scene 5 tiled): three rounds; the project's
# synth frame (bench/denoise.py --real ""): two.
. /work/main/runs/generalization-s24/common.sh
F=/work/data/heldout_g1_s5/scene_0005/deepz/noisy_spp16.0000.exr
run() {  # run WHERE LOG ARGS...: bench/denoise.py in that checkout
    ( cd $1 && PYTHONPATH=$1 python bench/denoise.py --real "" "${@:3}" ) > $2 2>&1
}
for r in 1 2 3; do
    run /work/wt_s24 s24/bench_r${r}_before.log --frame $F
    run /work/main s24/bench_r${r}_after.log --frame $F
done
for r in 1 2; do
    run /work/wt_s24 s24/bench_synth_r${r}_before.log
    run /work/main s24/bench_synth_r${r}_after.log
done
echo done > s24/bench_rounds.done
