#!/bin/bash
# session 24, fifth: glass at high spp (section 4). v7 fine-tuned gently on v6's pool (its windows family holds the
# training set's refraction) with the 64- and 128-spp crops drawn twice as often as in v6's recipe, then scored on
# the glass sets and on fog and interior (what it may cost), against v7 and the noisy input.
. /work/main/runs/generalization-s24/common.sh
R=/work/main/runs/cpu-small-pdl-gzw-t8
[ -f $R/train.done ] || { ( time ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R --config cpu-small-pdl-gza --steps 1500 --crop 64 --lr 5e-5 --seed 20 --init cpu-small-pdl-gza-v7 \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=4 \
    --spp-weight 128=4 --rotate-normals 0.5 ) > s24/train_gzw_t8.log 2>&1 && touch $R/train.done; }
for s in heldout_g1sg8 heldout_g1ac8 heldout_g1sp heldout_g1w4 heldout_g1fog heldout_g1int8; do
    ev t8 $s $R
done
echo done > s24/chain5.done
