# session 26: v7 with its output brought to flat OIDN's regional light (ev_gain.py R G)
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
gn() { [ -f s26/ev_g$1_$2_$3/eval.md ] || ( time python /work/main/runs/generalization-s26/ev_gain.py $1 $2 $3 \
    -o s26/ev_g$1_$2_$3 --model cpu-small-pdl-gza-v7 --held-out glass,layers,interior,fog --grid 0 ) \
    > s26/ev_g$1_$2_$3.log 2>&1; }
gn 8 2 heldout_g1w4
# gn 8 2 heldout_g1ac8   (not run: the first set said enough)
# gn 8 2 heldout_g1sg8   (not run)
gn 8 2 heldout_g1w4_r4k
touch s26/chain1.done
