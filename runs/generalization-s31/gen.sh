# The held-out sets of chain1.sh, rendered again (their folders are not kept between sessions); recipes from
# session 27's chains, the Gaussian-filtered ones with --pixel-filter gaussian (synth's default film became box after
# they were first made, so --filter-width alone now renders box frames)
S=s31
. /work/main/runs/generalization-s27/common.sh
S=s31
syn heldout_g1int8_box --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler stratified --pixel-filter box
syn heldout_g1int8_boxsob --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --sampler sobol --pixel-filter box
syn heldout_g1sg8_boxsob --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --sampler sobol \
    --pixel-filter box
syn heldout_g1int8 --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --pixel-filter gaussian --filter-width 2
syn heldout_g1fog_boxsob --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --sampler sobol --pixel-filter box
syn heldout_g1sg8 --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --pixel-filter gaussian \
    --filter-width 2
touch s31/gen.done
