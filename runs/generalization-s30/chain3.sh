#!/bin/bash
# session 30: a third backbone U-Net (cpu-small-pdl-gza-u3), grown from v7 as the identity (grow_unet.py) and
# fine-tuned by fl-t1's recipe exactly, so that it compares with fl-t1 (the same recipe on the two-U-Net v7); scored
# without light matching on the nine held-out sets, as session 28 scored fl-t1
. "$(dirname "$0")/common.sh"
[ -f $S/v7_u3_init.safetensors ] || python $R/generalization-s30/grow_unet.py cpu-small-pdl-gza-v7 \
    cpu-small-pdl-gza-u3 $S/v7_u3_init.safetensors || exit 1
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-u3fl-t1 --config cpu-small-pdl-gza-u3 \
    --steps 2000 --lr 1e-4 --seed 28 $T16_OPTS --init $S/v7_u3_init.safetensors --loss-weight flip=2 \
    ) >> $S/train_u3fl.log 2>&1
for s in $HELDOUT9; do evn u3fl $s $R/cpu-small-pdl-gza-u3fl-t1/checkpoint.pt; done
touch $S/chain3.done
