#!/bin/bash
# session 27: the held-out sets box-filtered (flat OIDN's own assumption: uncorrelated noise between pixels), with
# stratified and with Sobol samples, the same seeds as their Gaussian-2 originals; v7 scored on each
. "$(dirname "$0")/common.sh"
syn heldout_g1int8_boxsob --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler sobol --pixel-filter box
ev v7 heldout_g1int8_boxsob cpu-small-pdl-gza-v7
syn heldout_g1int8_box --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler stratified --pixel-filter box
ev v7 heldout_g1int8_box cpu-small-pdl-gza-v7
syn heldout_g1fog_boxsob --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --sampler sobol --pixel-filter box
ev v7 heldout_g1fog_boxsob cpu-small-pdl-gza-v7
syn heldout_g1sg8_boxsob --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers \
    --sampler sobol --pixel-filter box
ev v7 heldout_g1sg8_boxsob cpu-small-pdl-gza-v7
touch s27/chain3.done
