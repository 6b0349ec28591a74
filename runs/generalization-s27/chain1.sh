#!/bin/bash
# session 27: the held-out sets rendered again with `--sampler sobol` (every dimension from scrambled Sobol pairs,
# as production renderers sample), the same seeds and so the same scenes as their stratified originals
# (runs/generalization-s22/chain.sh), then v7 scored on them
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
syn() { [ -f s27/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --ref-spp 1024 --workers 2 \
    --sampler sobol --pixel-filter gaussian "${@:2}" ) > s27/synth_$1.log 2>&1 && touch s27/$1.done; }; }
ev() { [ -f s27/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s27/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s27/ev_$1_$2.log 2>&1; }
syn heldout_g1sg8_sob --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --filter-width 2
ev v7 heldout_g1sg8_sob cpu-small-pdl-gza-v7
syn heldout_g1int8_sob --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --filter-width 2
ev v7 heldout_g1int8_sob cpu-small-pdl-gza-v7
syn heldout_g1fog_sob --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --filter-width 2
ev v7 heldout_g1fog_sob cpu-small-pdl-gza-v7
touch s27/chain1.done
