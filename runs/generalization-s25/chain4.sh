# session 25: the composite_coarse term (energy at 4-8 px blocks): v7 fine-tuned gently on v6's pool with it (the
# recipe of session 24's t9 with this term instead of composite_grad), scored on the held-out sets
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
R=/work/main/runs/cpu-small-pdl-gzw-t10
[ -f $R/train.done ] || { ( time ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R --config cpu-small-pdl-gza --steps 1500 --crop 64 --lr 5e-5 --seed 22 --init cpu-small-pdl-gza-v7 \
    --loss-weight alpha=2 --loss-weight separation=1 --loss-weight composite_coarse=2 --checkpoint-every 200 \
    --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) > s25/train_gzw_t10.log 2>&1 \
    && touch $R/train.done; }
ev() { [ -f s25/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s25/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s25/ev_$1_$2.log 2>&1; }
for s in heldout_g1w4_r4k heldout_g1w4 heldout_g1ac8 heldout_g1sg8 heldout_g1fog heldout_g1int8; do
    ev t10 $s $R
done
touch s25/chain4.done
