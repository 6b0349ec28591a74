#!/bin/bash
# session 28: the HDR-FLIP term with a balanced pool (box-filtered Sobol, Gaussian Sobol and v6's sets, each once),
# 3000 steps; and the weights half-way between v7 and chain2's run (robust fine-tuning's interpolation, as v7 is
# between v5 and v6); both scored on the box and the Gaussian held-out sets
. "$(dirname "$0")/common.sh"
while [ ! -f $S/chain2.done ]; do sleep 20; done
( time OMP_NUM_THREADS=2 ranad train train_g35_boxsob train_g34_sob train_g33_win train_g31_sub train_g30_sub \
    -o $R/cpu-small-pdl-gza-fl-t2 --config cpu-small-pdl-gza --steps 3000 --lr 1e-4 --seed 29 $T16_OPTS \
    --init cpu-small-pdl-gza-v7 \
    --loss-weight flip=2 ) >> $S/train_flt2.log 2>&1
ev_sets flt2 $R/cpu-small-pdl-gza-fl-t2/checkpoint.pt $HELDOUT9
[ -f $S/flt1_half.safetensors ] || ranad export $R/cpu-small-pdl-gza-fl-t1 -o $S/flt1_half.safetensors \
    --interpolate cpu-small-pdl-gza-v7=0.5 > $S/export_flt1_half.log 2>&1
ev_sets flt1h $S/flt1_half.safetensors $HELDOUT9
touch $S/chain3.done
