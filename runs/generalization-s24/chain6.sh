#!/bin/bash
# session 24, sixth: which layer's kernels cost the glass scenes at 64 spp (section 4)? v7 with its diffuse, then
# its specular reconstruction replaced by the noisy layer, on the box glass-and-layers set.
. /work/main/runs/generalization-s24/common.sh
for l in specular diffuse; do
    [ -f s24/ev_v7keep_${l}_heldout_g1ac8/eval.md ] || ( time python /work/main/runs/generalization-s24/ev_keep_layer.py \
        $l heldout_g1ac8 -o s24/ev_v7keep_${l}_heldout_g1ac8 --model cpu-small-pdl-gza-v7 \
        --held-out glass,layers,interior,fog --grid 0 ) > s24/ev_v7keep_${l}_heldout_g1ac8.log 2>&1
done
echo done > s24/chain6.done
