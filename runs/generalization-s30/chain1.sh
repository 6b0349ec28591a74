#!/bin/bash
# session 30: the fourth diffuse scale again (session 28's cpu-small-pdl-gza-d4, grown from v7 by its grow_init.py),
# now with the HDR-FLIP term: fl-t1's recipe exactly (data, steps, lr, seed), so that it compares with fl-t1; scored
# without light matching on the nine held-out sets, as session 28 scored fl-t1
. "$(dirname "$0")/common.sh"
[ -f s28/v7_d4_init.safetensors ] || python $R/generalization-s28/grow_init.py cpu-small-pdl-gza-v7 \
    cpu-small-pdl-gza-d4 s28/v7_d4_init.safetensors -1.0 || exit 1
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-d4fl-t1 --config cpu-small-pdl-gza-d4 \
    --steps 2000 --lr 1e-4 --seed 28 $T16_OPTS --init s28/v7_d4_init.safetensors --loss-weight flip=2 \
    ) >> $S/train_d4fl.log 2>&1
# (stopped by hand during the fifth set: the first four within 0.2-1.4% of fl-t1's; README section 1)
for s in $HELDOUT9; do evn d4fl $s $R/cpu-small-pdl-gza-d4fl-t1/checkpoint.pt; done
touch $S/chain1.done
