# the v9 candidate (export_v9.sh) beside v8: session 27's in-family sets rendered again from their recipe
# (runs/generalization-s27/chain6.sh), the exposure sweep of v8's card, and session 32's guide-less copies
# (red32_*: base and noaux, 4 and 16 spp) for the README's figures on files without guides.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
V9=/work/main/ranad_core/weights/cpu-small-pdl-gza-v9.safetensors
syn infam_g36_box --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler stratified --pixel-filter box
syn infam_g36_boxsob --scenes 8 --spp 4,16,64 --seed 36 --preset medium --preset studio --preset textured \
    --preset exterior --sampler sobol --pixel-filter box
for s in infam_g36_box infam_g36_boxsob; do
  ev v9 $s $V9
  ev v8 $s cpu-small-pdl-gza-v8
done
[ -f $S/evx9/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/evx9 --model $V9 \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > $S/evx9.log 2>&1
for s in heldout_g1int8_box heldout_g1int8 heldout_g1sg8_boxsob; do
  for spp in 4 16; do
    for kind in noaux base; do ev v9 red32_${kind}_${spp}_$s $V9; done
  done
done
touch $S/chain4.done
