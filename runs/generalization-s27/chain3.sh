#!/bin/bash
# session 27: the held-out sets box-filtered (flat OIDN's own assumption: uncorrelated noise between pixels), with
# stratified and with Sobol samples, the same seeds as their Gaussian-2 originals; v7 scored on each
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
syn() { [ -f s27/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --ref-spp 1024 --workers 2 \
    --pixel-filter box "${@:2}" ) > s27/synth_$1.log 2>&1 && touch s27/$1.done; }; }
ev() { [ -f s27/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s27/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s27/ev_$1_$2.log 2>&1; }
syn heldout_g1int8_boxsob --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler sobol
ev v7 heldout_g1int8_boxsob cpu-small-pdl-gza-v7
syn heldout_g1int8_box --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler stratified
ev v7 heldout_g1int8_box cpu-small-pdl-gza-v7
syn heldout_g1fog_boxsob --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --sampler sobol
ev v7 heldout_g1fog_boxsob cpu-small-pdl-gza-v7
syn heldout_g1sg8_boxsob --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --sampler sobol
ev v7 heldout_g1sg8_boxsob cpu-small-pdl-gza-v7
touch s27/chain3.done
