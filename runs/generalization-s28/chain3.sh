#!/bin/bash
# session 28: the HDR-FLIP term with a balanced pool (box-filtered Sobol, Gaussian Sobol and v6's sets, each once),
# 3000 steps; and the weights half-way between v7 and chain2's run (robust fine-tuning's interpolation, as v7 is
# between v5 and v6); both scored on the box and the Gaussian held-out sets
S=s28
. "$(dirname "$0")/../generalization-s27/common.sh"
while [ ! -f $S/chain2.done ]; do sleep 20; done
( time OMP_NUM_THREADS=2 ranad train train_g35_boxsob train_g34_sob train_g33_win train_g31_sub train_g30_sub \
    -o $R/cpu-small-pdl-gza-fl-t2 --config cpu-small-pdl-gza --steps 3000 --crop 64 --lr 1e-4 --seed 29 \
    --init cpu-small-pdl-gza-v7 --loss-weight alpha=2 --loss-weight separation=1 --loss-weight flip=2 \
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 \
    ) >> $S/train_flt2.log 2>&1
SETS="heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob heldout_g1sg8
      heldout_g1w4 heldout_g1ac8 heldout_g1fog"
for s in $SETS; do ev flt2 $s $R/cpu-small-pdl-gza-fl-t2/checkpoint.pt; done
[ -f $S/flt1_half.safetensors ] || ranad export $R/cpu-small-pdl-gza-fl-t1 -o $S/flt1_half.safetensors \
    --interpolate cpu-small-pdl-gza-v7=0.5 > $S/export_flt1_half.log 2>&1
for s in $SETS; do ev flt1h $s $S/flt1_half.safetensors; done
touch $S/chain3.done
