#!/bin/bash
# session 23, third: v6 lost 1.5% to v5 on box-filtered held-out shots (heldout_g3s2; its pool is all Gaussian-
# filtered): v6's recipe again from v6 with the box-filtered centre frames of train_g3 and train_g3s added (a third
# of the scenes), then scored on the Gaussian sets, the turned one and the box-filtered shots
. "$(dirname "$0")/common.sh"
R=/work/main/runs
[ -f $R/cpu-small-pdl-gzw-t6/train.done ] || { ( time OMP_NUM_THREADS=2 ranad train train_g33_win train_g31_sub \
    train_g31_sub train_g30_sub train_g30_sub train_g3 train_g3s -o $R/cpu-small-pdl-gzw-t6 \
    --config cpu-small-pdl-gza --steps 3000 --crop 64 --lr 1e-4 --seed 18 --init cpu-small-pdl-gza-v6 \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 \
    --spp-weight 128=2 --rotate-normals 0.5 ) > s23/train_gzw6.log 2>&1 && touch $R/cpu-small-pdl-gzw-t6/train.done; }
[ -f s23/evt_gzw6/temporal.md ] || ( time ranad eval heldout_g3s2 -o s23/evt_gzw6 --temporal \
    --model $R/cpu-small-pdl-gzw-t6 --cross-model s23/xg6.safetensors ) > s23/evt_gzw6.log 2>&1
for s in heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1sg8_rot; do
    ev gzw6 $s $R/cpu-small-pdl-gzw-t6
done
echo done > s23/chain3.done
