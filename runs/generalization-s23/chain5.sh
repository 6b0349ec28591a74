#!/bin/bash
# session 23, fifth: heldout_g3s2's shots again through a Gaussian of width 2 with stratified samples (the filter and
# sampler of v6's pool and of heldout_g1sg8), to score the cross-frame pairs where v6 is ahead on single frames
cd /work/data
. /work/main/.venv/bin/activate
while [ ! -f s23/chain4.done ]; do sleep 10; done
[ -f s23/heldout_g3s2g.done ] || { ( time ranad synth -o heldout_g3s2g --scenes 6 --size 128 --frames 3 --spp 4,16 \
    --ref-spp 1024 --seed 1023 --workers 2 --preset glass --preset layers --motion 0.25 --ref-frames all \
    --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s23/synth_heldout_g3s2g.log 2>&1 \
    && touch s23/heldout_g3s2g.done; }
[ -f s23/evtg_v5/temporal.md ] || ( time ranad eval heldout_g3s2g -o s23/evtg_v5 --temporal \
    --model cpu-small-pdl-gza-v5 --cross-model cpu-small-pdl-gza-xg-v5 ) > s23/evtg_v5.log 2>&1
[ -f s23/evtg_v6/temporal.md ] || ( time ranad eval heldout_g3s2g -o s23/evtg_v6 --temporal \
    --model cpu-small-pdl-gza-v6 --cross-model s23/xg6.safetensors ) > s23/evtg_v6.log 2>&1
echo done > s23/chain5.done
