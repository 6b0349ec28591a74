#!/bin/bash
# session 24, third: how far a seed moves v7. v6's fine-tune again from v5 with another seed (its card's command,
# --seed 19 instead of 16), interpolated half-way with v5 as v7 was (export.sh of session 23, halo measured), scored
# on the five single-frame sets of section 2: the spread of v7's recipe, against which the ~1% differences of
# sections 1-2 (and of session 23's choices) are read.
. /work/main/runs/generalization-s24/common.sh
while [ ! -f s24/bench_rounds.done ]; do sleep 10; done
R=/work/main/runs/cpu-small-pdl-gzw-t7
[ -f $R/train.done ] || { ( time ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R --config cpu-small-pdl-gza --steps 3000 --crop 64 --lr 1e-4 --seed 19 --init cpu-small-pdl-gza-v5 \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 \
    --spp-weight 128=2 --rotate-normals 0.5 ) > s24/train_gzw_t7.log 2>&1 && touch $R/train.done; }
[ -f s24/v7s19.safetensors ] || /work/main/runs/generalization-s23/export.sh $R s24/v7s19.safetensors \
    --interpolate cpu-small-pdl-gza-v5=0.5 > s24/export_v7s19.log 2>&1
for s in heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1ac8 heldout_g1w4; do
    ev v7s19 $s s24/v7s19.safetensors
done
echo done > s24/chain3.done
