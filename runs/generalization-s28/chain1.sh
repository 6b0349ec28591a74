#!/bin/bash
# session 28: a fourth diffuse scale (cpu-small-pdl-gza-d4), started from v7 (grow_init.py: the new scale a copy of
# the coarsest), fine-tuned with session 27's t16 recipe (same data, steps and seed), scored on the box and the
# Gaussian held-out sets
. "$(dirname "$0")/common.sh"
[ -f $S/v7_d4_init.safetensors ] || python $R/generalization-s28/grow_init.py cpu-small-pdl-gza-v7 \
    cpu-small-pdl-gza-d4 $S/v7_d4_init.safetensors -1.0 || exit 1
( time OMP_NUM_THREADS=2 ranad train $T16_POOL -o $R/cpu-small-pdl-gza-d4-t1 --config cpu-small-pdl-gza-d4 \
    --steps 2000 --lr 5e-5 --seed 28 $T16_OPTS --init $S/v7_d4_init.safetensors ) >> $S/train_d4t1.log 2>&1
ev_sets d4t1 $R/cpu-small-pdl-gza-d4-t1/checkpoint.pt $HELDOUT9
touch $S/chain1.done
