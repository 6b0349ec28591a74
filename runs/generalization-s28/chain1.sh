#!/bin/bash
# session 28: a fourth diffuse scale (cpu-small-pdl-gza-d4), started from v7 (grow_init.py: the new scale a copy of
# the coarsest), fine-tuned with session 27's t16 recipe (same data, steps and seed), scored on the box and the
# Gaussian held-out sets
S=s28
. "$(dirname "$0")/../generalization-s27/common.sh"
[ -f $S/v7_d4_init.safetensors ] || python $R/generalization-s28/grow_init.py cpu-small-pdl-gza-v7 \
    cpu-small-pdl-gza-d4 $S/v7_d4_init.safetensors -1.0 || exit 1
( time OMP_NUM_THREADS=2 ranad train train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub \
    -o $R/cpu-small-pdl-gza-d4-t1 --config cpu-small-pdl-gza-d4 --steps 2000 --crop 64 --lr 5e-5 --seed 28 \
    --init $S/v7_d4_init.safetensors --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
    --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) >> $S/train_d4t1.log 2>&1
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
    heldout_g1sg8 heldout_g1w4 heldout_g1ac8 heldout_g1fog; do
    ev d4t1 $s $R/cpu-small-pdl-gza-d4-t1/checkpoint.pt
done
touch $S/chain1.done
