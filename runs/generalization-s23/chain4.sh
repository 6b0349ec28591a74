#!/bin/bash
# session 23, fourth: a box-filtered single-frame held-out set (the first 8 scenes of v5's heldout_g1ac) for v5, v6
# and gzw6, as v5's card scored it (flat and edit against OIDN's)
. "$(dirname "$0")/common.sh"
R=/work/main/runs
while [ ! -f s23/chain3.done ]; do sleep 10; done
[ -f s23/heldout_g1ac8.done ] || { ( time ranad synth -o heldout_g1ac8 --scenes 8 --size 128 --frames 1 \
    --spp 4,16,64 --ref-spp 1024 --seed 1095 --workers 2 --preset glass --preset layers ) \
    > s23/synth_heldout_g1ac8.log 2>&1 && touch s23/heldout_g1ac8.done; }
ev v5 heldout_g1ac8 cpu-small-pdl-gza-v5
ev v6 heldout_g1ac8 cpu-small-pdl-gza-v6
ev gzw6 heldout_g1ac8 $R/cpu-small-pdl-gzw-t6
echo done > s23/chain4.done
