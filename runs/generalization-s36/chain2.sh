#!/bin/bash
# session 36, second (after chain1.sh): what shipping e1 would need, run whatever the tables say: a cross-frame model
# on e1's weights by xg-v8's recipe (session 34's xgt), scored on the two held-out shot sets, and the exposure sweep.
# (Stopped during the cross-frame training, its run folder removed: chain1's tables said e1 was not to be shipped.)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
while [ ! -f $S/chain1.done ]; do sleep 20; done
xgt e1 $S/e1.safetensors || exit 1
for s in heldout_g3s2 heldout_g3s2g; do evt xge1 $s $S/e1.safetensors $S/xge1.safetensors; done
[ -f $S/evxe1/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/evxe1 --model $S/e1.safetensors \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > $S/evxe1.log 2>&1
touch $S/chain2.done
