#!/bin/bash
# session 35, second (after chain1.sh): the pool-trained model interpolated half-way back to v9's weights (as v7 and
# v8 were made), which may keep the flat gains of the larger pool with fewer of its edit losses; scored on the same
# sets. A study row: exported after chain1 and scored as p2 was.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
while [ ! -f $S/chain1.done ]; do sleep 20; done
[ -f $S/p2i.safetensors ] || bash $R/generalization-s23/export.sh $R/cpu-small-pdl-gza-c128p2-t1 $S/p2i.safetensors \
    --interpolate cpu-small-pdl-gza-v9=0.5 > $S/export_p2i.log 2>&1 || exit 1
for s in $SETS; do ev p2i $s $S/p2i.safetensors; done
touch $S/chain2.done
