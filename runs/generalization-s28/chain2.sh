#!/bin/bash
# session 28: v7 fine-tuned with the HDR-FLIP term (--loss-weight flip=2), otherwise session 27's t16 recipe at lr
# 1e-4; scored on the box and the Gaussian held-out sets
. "$(dirname "$0")/common.sh"
while [ ! -f $S/chain1.done ]; do sleep 20; done
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-fl-t1 --config cpu-small-pdl-gza \
    --steps 2000 --lr 1e-4 --seed 28 $T16_OPTS --init cpu-small-pdl-gza-v7 --loss-weight flip=2 \
    ) >> $S/train_flt1.log 2>&1
ev_sets flt1 $R/cpu-small-pdl-gza-fl-t1/checkpoint.pt $HELDOUT9
touch $S/chain2.done
