#!/bin/bash
# session 24, eighth: the composite_grad term (section 4's lead): v7 fine-tuned gently on v6's pool with it, scored on
# the windows training scenes and the glass-and-layers, fog and interior held-out sets.
. /work/main/runs/generalization-s24/common.sh
R=/work/main/runs/cpu-small-pdl-gzw-t9
[ -f $R/train.done ] || { ( time ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R --config cpu-small-pdl-gza --steps 1500 --crop 64 --lr 5e-5 --seed 21 --init cpu-small-pdl-gza-v7 \
    --loss-weight alpha=2 --loss-weight separation=1 --loss-weight composite_grad=4 --checkpoint-every 200 \
    --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) > s24/train_gzw_t9.log 2>&1 \
    && touch $R/train.done; }
[ -f s24/ev_t9_train_g33_win/eval.md ] || ( time ranad eval train_g33_win -o s24/ev_t9_train_g33_win --model $R \
    --scenes 8 --kind deepz --spp 16,64,128 --grid 0 ) > s24/ev_t9_train_g33_win.log 2>&1
for s in heldout_g1ac8 heldout_g1sg8 heldout_g1fog heldout_g1int8; do
    ev t9 $s $R
done
echo done > s24/chain8.done
