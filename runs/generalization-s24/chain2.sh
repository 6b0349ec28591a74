#!/bin/bash
# session 24, second: a uniform soup of the three fine-tunes of v5 that session 22-23 trained on different pools:
# v6 (windows, turned normals), v5 itself, gzw6 (v6's pool plus box-filtered frames; not shipped: better on box
# frames, worse on fog at 4 spp). v7 is (v5 + v6) / 2, so the soup is v7 2/3 + gzw6 1/3. One candidate, scored on
# every single-frame held-out set v7's card reports.
. /work/main/runs/generalization-s24/common.sh
while [ ! -f s24/chain1.done ]; do sleep 10; done
[ -f s24/soup3.safetensors ] || /work/main/runs/generalization-s23/export.sh /work/main/runs/cpu-small-pdl-gzw-t6 \
    s24/soup3.safetensors --interpolate cpu-small-pdl-gza-v7=0.6666666666666666 > s24/export_soup3.log 2>&1
for s in heldout_g1ac8 heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1w4 heldout_g1sp heldout_g1sg8_rot \
         heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_yaw; do
    ev soup3 $s s24/soup3.safetensors
done
echo done > s24/chain2.done
