#!/bin/bash
# session 23, sixth: v5 and v6 weights interpolated half-way (robust fine-tuning's weight interpolation: v6 is v5
# fine-tuned), scored on every set v5 and v6 were
. "$(dirname "$0")/common.sh"
while [ ! -f s23/chain5.done ]; do sleep 10; done
for s in heldout_g1ac8 heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1sg8_rot; do
    ev mix50 $s s23/mix50.safetensors
done
[ -f s23/evt_mix50/temporal.md ] || ( time ranad eval heldout_g3s2 -o s23/evt_mix50 --temporal \
    --model s23/mix50.safetensors --cross-model cpu-small-pdl-gza-xg-v5 ) > s23/evt_mix50.log 2>&1
echo done > s23/chain6.done
