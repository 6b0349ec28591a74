#!/bin/bash
# session 23, eighth: the shipped v7 file itself on the single-frame sets (mix50, the scratch file chain6 scored, was
# interpolated in float32; the export interpolates in float64)
. "$(dirname "$0")/common.sh"
while [ ! -f s23/chain7.done ]; do sleep 10; done
for s in heldout_g1ac8 heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1sg8_rot heldout_g1sg8_yaw \
         heldout_g1fog_rot heldout_g1int8_rot heldout_g1w4; do
    ev v7 $s cpu-small-pdl-gza-v7
done
echo done > s23/chain8.done
