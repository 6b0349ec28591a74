#!/bin/bash
# session 27: the weights half-way between v7 and t16 (as v7 is between v5 and v6), scored on the same sets
. "$(dirname "$0")/common.sh"
M=s27/t16_half.safetensors
[ -f $M ] || ranad export $R/cpu-small-pdl-gzb-t16 -o $M --interpolate cpu-small-pdl-gza-v7=0.5 \
    > s27/export_t16_half.log 2>&1
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1fog_boxsob heldout_g1sg8_boxsob heldout_g1int8 \
    heldout_g1sg8 heldout_g1w4 heldout_g1ac8 heldout_g1fog; do
    ev t16h $s $M
done
touch s27/chain5.done
