# session 25: heldout_g1w4's glass scenes with 4096-spp references, then v7 scored on them
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
mkdir -p heldout_g1w4_r4k
(time python s25/make_ref.py heldout_g1w4 heldout_g1w4_r4k 4096 scene_0000 scene_0002 scene_0004 scene_0006) \
    > s25/make_ref_w4.log 2>&1
[ -f s25/ev_v7_heldout_g1w4_r4k/eval.md ] || (time ranad eval heldout_g1w4_r4k -o s25/ev_v7_heldout_g1w4_r4k \
    --model cpu-small-pdl-gza-v7 --held-out glass,layers,interior,fog --grid 0) > s25/ev_v7_heldout_g1w4_r4k.log 2>&1
touch s25/chain3.done
