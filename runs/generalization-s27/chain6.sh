#!/bin/bash
# session 27: in-family opaque scenes (fresh seed) box-filtered, stratified and Sobol: does v7 trail flat OIDN there
# too (capacity), or only on the held-out interiors (generalization)?
. "$(dirname "$0")/common.sh"
syn infam_g36_box --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler stratified --pixel-filter box
ev v7 infam_g36_box cpu-small-pdl-gza-v7
syn infam_g36_boxsob --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler sobol --pixel-filter box
ev v7 infam_g36_boxsob cpu-small-pdl-gza-v7
touch s27/chain6.done
