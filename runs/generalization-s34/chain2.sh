#!/bin/bash
# session 34, second (after chain1.sh): a v10 candidate, v9 + another 3000 steps of v8's recipe on v8's pool at
# --crop 128 (session 33's chain2.sh again from v9's weights, a new seed), scored on every held-out set of v9's and
# v8's cards, in-family, the exposure sweep; then a cross-frame model on it by xg-v8's recipe, on the two shot sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
while [ ! -f $S/chain1.done ]; do sleep 20; done
C=$R/cpu-small-pdl-gza-c128g3-t1
trn c128g3-t1 $V8_POOL $V8_OPTS --steps 3000 --crop 128 --init $V9 --seed 34 || exit 1
[ -f $S/v10.safetensors ] || bash $R/generalization-s23/export.sh $C $S/v10.safetensors > $S/export_v10.log 2>&1 \
    || exit 1
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8 heldout_g1ac8 heldout_g1sp heldout_g1fog heldout_g1w4 heldout_g1fog_rot heldout_g1int8_rot \
         heldout_g1sg8_rot heldout_g1sg8_yaw infam_g36_box infam_g36_boxsob; do
    ev v10 $s $S/v10.safetensors
done
xgt 10 $S/v10.safetensors || exit 1
for s in heldout_g3s2 heldout_g3s2g; do evt xg10 $s $S/v10.safetensors $S/xg10.safetensors; done
[ -f $S/evx10/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/evx10 --model $S/v10.safetensors \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > $S/evx10.log 2>&1
touch $S/chain2.done
