#!/bin/bash
# session 28: fl-t1's recipe with the HDR-FLIP term on the compositing edit too (--loss-weight edit_flip=2), scored
# on four held-out sets whose edit figures miss the issue's target
. "$(dirname "$0")/common.sh"
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-fl-t4 --config cpu-small-pdl-gza \
    --steps 2000 --lr 1e-4 --seed 28 $T16_OPTS --init cpu-small-pdl-gza-v7 --loss-weight flip=2 \
    --loss-weight edit_flip=2 ) >> $S/train_flt4.log 2>&1
ev_sets flt4 $R/cpu-small-pdl-gza-fl-t4/checkpoint.pt heldout_g1int8_box heldout_g1sg8_boxsob heldout_g1w4 \
    heldout_g1ac8
touch $S/chain6.done
