#!/bin/bash
# session 30: chain3's third U-Net barely left the identity at lr 1e-4 (its residual outputs at 2-3% of the other
# U-Nets' norms after 2000 steps). The same at lr 5e-4, and as the control the same recipe at lr 5e-4 on the
# two-U-Net v7; scored without light matching on five of the held-out sets
. "$(dirname "$0")/common.sh"
SETS5="heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob"
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-u3fl-t2 --config cpu-small-pdl-gza-u3 \
    --steps 2000 --lr 5e-4 --seed 28 $T16_OPTS --init $S/v7_u3_init.safetensors --loss-weight flip=2 \
    ) >> $S/train_u3fl2.log 2>&1
for s in $SETS5; do evn u3fl2 $s $R/cpu-small-pdl-gza-u3fl-t2/checkpoint.pt; done
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-fl-t5 --config cpu-small-pdl-gza \
    --steps 2000 --lr 5e-4 --seed 28 $T16_OPTS --init cpu-small-pdl-gza-v7 --loss-weight flip=2 \
    ) >> $S/train_flt5.log 2>&1
for s in $SETS5; do evn flt5 $s $R/cpu-small-pdl-gza-fl-t5/checkpoint.pt; done
touch $S/chain4.done
