# two more of v8's card's sets for v9, rendered again from their recipes (runs/generalization-s23/chain4.sh and
# chain9.sh): box-filtered glass and layers with stratified samples (heldout_g1ac8) and glass and layers at 1 / 2 /
# 128 spp through a Gaussian of width 2 (heldout_g1sp); v8 and v9 scored on both.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
V9=/work/main/ranad_core/weights/cpu-small-pdl-gza-v9.safetensors
syn heldout_g1ac8 --scenes 8 --spp 4,16,64 --seed 1095 --preset glass --preset layers
for m in v9 v8; do ev $m heldout_g1ac8 cpu-small-pdl-gza-$m; done
[ -f $S/heldout_g1sp.done ] || { ( time ranad synth -o heldout_g1sp --size 128 --frames 1 --workers 2 --scenes 8 \
    --spp 1,2,128 --ref-spp 2048 --seed 1099 --preset glass --preset layers --pixel-filter gaussian \
    --filter-width 2 ) > $S/synth_heldout_g1sp.log 2>&1 && touch $S/heldout_g1sp.done; }
for m in v9 v8; do ev $m heldout_g1sp cpu-small-pdl-gza-$m; done
touch $S/chain5.done
