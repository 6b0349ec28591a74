# The two Gaussian-filtered sets again (gen.sh's first recipes lacked --pixel-filter gaussian and rendered box
# frames; those folders and their evaluations were deleted), then chain1.sh's evaluations of heldout_g1int8
# (chain1.sh itself waits for heldout_g1sg8)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
syn heldout_g1int8 --scenes 8 --spp 4,16,64 --seed 1103 --preset interior --pixel-filter gaussian --filter-width 2
syn heldout_g1sg8 --scenes 8 --spp 4,16,64 --seed 1101 --preset glass --preset layers --pixel-filter gaussian \
    --filter-width 2
M=cpu-small-pdl-gza-v8
ev v8 heldout_g1int8 $M
evc prior cp heldout_g1int8 $M
evc baseline cb heldout_g1int8 $M
touch $S/chain3.done
