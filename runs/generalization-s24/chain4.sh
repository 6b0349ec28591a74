#!/bin/bash
# session 24, fourth: does the guided prior cost ranad the glass scenes? v7 with the prior's OIDN unguided (the model
# itself unchanged), on the box and Gaussian-2 glass-and-layers sets, against v7's own rows.
. /work/main/runs/generalization-s24/common.sh
while [ ! -f s24/chain3.done ]; do sleep 10; done
for s in heldout_g1ac8 heldout_g1sg8; do
    [ -f s24/ev_v7ng_$s/eval.md ] || ( time python /work/main/runs/generalization-s24/ev_noguide.py $s \
        -o s24/ev_v7ng_$s --model cpu-small-pdl-gza-v7 --held-out glass,layers,interior,fog --grid 0 ) \
        > s24/ev_v7ng_$s.log 2>&1
done
echo done > s24/chain4.done
