# session 25: test-time flip ensembles of v7 (ev_tta.py), K = 2 and 4, on the Gaussian-4 and box sets
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
tta() { [ -f s25/ev_tta$1_$2/eval.md ] || ( time python s25/ev_tta.py $1 $2 -o s25/ev_tta$1_$2 \
    --model cpu-small-pdl-gza-v7 --held-out glass,layers,interior,fog --grid 0 ) > s25/ev_tta$1_$2.log 2>&1; }
tta 2 heldout_g1w4
tta 4 heldout_g1w4
tta 2 heldout_g1ac8
tta 4 heldout_g1ac8
tta 4 heldout_g1sg8
tta 4 heldout_g1fog
touch s25/chain1.done
