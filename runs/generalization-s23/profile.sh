#!/bin/bash
# session 23: `ranad denoise --profile` on the held-out 1080p frame (s23/frame1080.exr, bench/denoise.py's
# make_1080p of heldout_g1_s5's scene 5), the session's starting code (/work/wt_old at 293c311) and now, alternating
# old, new, old, new, nothing else running; v6 on both
cd /work/data
. /work/main/.venv/bin/activate
n=0
for w in old new old new; do
    n=$((n + 1))
    if [ $w = old ]; then T=/work/wt_old; E="env -u NUMPY_MADVISE_HUGEPAGE"; else T=/work/main; E=env; fi
    ( cd $T && $E PYTHONPATH=$T python -m ranad_cli denoise /work/data/s23/frame1080.exr -o /tmp/p_$w.exr \
        --model cpu-small-pdl-gza-v6 --profile 2>&1 | grep -E '^\| ' ) > s23/profile_${w}_$n.txt
done
