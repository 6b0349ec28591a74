#!/bin/bash
# session 28: fl-t1's recipe with the HDR-FLIP term twice as strong (flip=4), scored on the nine held-out sets
. "$(dirname "$0")/common.sh"
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-fl-t3 --config cpu-small-pdl-gza \
    --steps 2000 --lr 1e-4 --seed 28 $T16_OPTS --init cpu-small-pdl-gza-v7 --loss-weight flip=4 \
    ) >> $S/train_flt3.log 2>&1
ev_sets flt3 $R/cpu-small-pdl-gza-fl-t3/checkpoint.pt $HELDOUT9
touch $S/chain5.done
