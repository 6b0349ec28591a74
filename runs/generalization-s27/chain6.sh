#!/bin/bash
# session 27: in-family opaque scenes (fresh seed) box-filtered, stratified and Sobol: does v7 trail flat OIDN there
# too (capacity), or only on the held-out interiors (generalization)?
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
syn() { [ -f s27/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --ref-spp 1024 --workers 2 \
    --pixel-filter box "${@:2}" ) > s27/synth_$1.log 2>&1 && touch s27/$1.done; }; }
ev() { [ -f s27/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s27/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s27/ev_$1_$2.log 2>&1; }
syn infam_g36_box --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler stratified
ev v7 infam_g36_box cpu-small-pdl-gza-v7
syn infam_g36_boxsob --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler sobol
ev v7 infam_g36_boxsob cpu-small-pdl-gza-v7
touch s27/chain6.done
