#!/bin/bash
# session 28: fl-t1's recipe with the HDR-FLIP term on the compositing edit too (--loss-weight edit_flip=2), scored
# on four held-out sets whose edit figures miss the issue's target
S=s28
. "$(dirname "$0")/../generalization-s27/common.sh"
( time OMP_NUM_THREADS=2 ranad train train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub \
    -o $R/cpu-small-pdl-gza-fl-t4 --config cpu-small-pdl-gza --steps 2000 --crop 64 --lr 1e-4 --seed 28 \
    --init cpu-small-pdl-gza-v7 --loss-weight alpha=2 --loss-weight separation=1 --loss-weight flip=2 \
    --loss-weight edit_flip=2 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 \
    --rotate-normals 0.5 ) >> $S/train_flt4.log 2>&1
for s in heldout_g1int8_box heldout_g1sg8_boxsob heldout_g1w4 heldout_g1ac8; do
    ev flt4 $s $R/cpu-small-pdl-gza-fl-t4/checkpoint.pt
done
touch $S/chain6.done
