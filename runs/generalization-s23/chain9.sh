#!/bin/bash
# session 23, ninth: the 1 / 2 / 128-spp held-out set (v5 card's heldout_g1sp, the recipe of session 20's note) for
# v5, v6 and v7
. "$(dirname "$0")/common.sh"
[ -f s23/heldout_g1sp.done ] || { ( time ranad synth -o heldout_g1sp --scenes 8 --size 128 --frames 1 --spp 1,2,128 \
    --ref-spp 2048 --seed 1099 --workers 2 --preset glass --preset layers --pixel-filter gaussian --filter-width 2 ) \
    > s23/synth_heldout_g1sp.log 2>&1 && touch s23/heldout_g1sp.done; }
for m in v5 v6 v7; do ev $m heldout_g1sp cpu-small-pdl-gza-$m; done
echo done > s23/chain9.done
