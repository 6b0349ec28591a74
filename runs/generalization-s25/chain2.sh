# session 25: v7 with its reconstruction kernels' content logits scaled (ev_temp.py), Gaussian-4 and box sets
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
tm() { [ -f s25/ev_t$1_$2_$3/eval.md ] || ( time python s25/ev_temp.py $1 $2 $3 -o s25/ev_t$1_$2_$3 \
    --model cpu-small-pdl-gza-v7 --held-out glass,layers,interior,fog --grid 0 ) > s25/ev_t$1_$2_$3.log 2>&1; }
tm 1.25 all heldout_g1w4
tm 0.8 all heldout_g1w4
tm 1.25 specular heldout_g1w4
tm 1.25 all heldout_g1ac8
touch s25/chain2.done
