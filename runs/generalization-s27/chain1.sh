#!/bin/bash
# session 27: the held-out sets rendered again with `--sampler sobol` (every dimension from scrambled Sobol pairs,
# as production renderers sample), the same seeds and so the same scenes as their stratified originals
# (runs/generalization-s22/chain.sh), then v7 scored on them
. "$(dirname "$0")/common.sh"
syn heldout_g1sg8_sob --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --filter-width 2 \
    --sampler sobol --pixel-filter gaussian
ev v7 heldout_g1sg8_sob cpu-small-pdl-gza-v7
syn heldout_g1int8_sob --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --filter-width 2 \
    --sampler sobol --pixel-filter gaussian
ev v7 heldout_g1int8_sob cpu-small-pdl-gza-v7
syn heldout_g1fog_sob --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --filter-width 2 \
    --sampler sobol --pixel-filter gaussian
ev v7 heldout_g1fog_sob cpu-small-pdl-gza-v7
touch s27/chain1.done
