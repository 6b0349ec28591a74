#!/bin/bash
# session 22, last: the wide-filter held-out sets where v5 missed the edit target (runs/pixel-filter-s18's recipes;
# gauss3 its first 8 scenes), v5 and v6 on each
cd /work/data
. /work/main/.venv/bin/activate
while pgrep -f "pytest -q -p no:cacheprovider" > /dev/null; do sleep 5; done
syn() { [ -f s22/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --workers 2 "${@:2}" ) \
    > s22/synth_$1.log 2>&1 && touch s22/$1.done; }; }
syn heldout_g1w4 --scenes 8 --spp 4,16,64 --ref-spp 512 --seed 1097 --preset glass --preset layers \
    --pixel-filter gaussian --filter-width 4
syn heldout_g1ab_gauss3_8 --scenes 8 --spp 4,16,64 --ref-spp 1024 --seed 1093 --preset glass --preset layers \
    --pixel-filter gaussian --filter-width 3
ev() { [ -f s22/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s22/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s22/ev_$1_$2.log 2>&1; }
for s in heldout_g1w4 heldout_g1ab_gauss3_8; do
    ev v5 $s cpu-small-pdl-gza-v5
    ev v6 $s cpu-small-pdl-gza-v6
done
echo done > s22/chain5.done
