# Files without guides (chain3.sh: ranad loses 4-5% of its flat FLIP on the box-filtered interiors when the albedo
# and normal are missing, flat OIDN nothing): v8 fine-tuned 1000 steps by its own recipe on its whole pool (session
# 28's fl-t1 recipe from v8's weights), once with half the crops shown without guides (pna5-t1: --p-no-aux 0.5) and
# once with the default fifth (pna2-t1, the control), then both on chain3.sh's reduced copies (base, noaux) of three
# held-out sets. The pool's three Gaussian-filtered sets are rendered again from v6's card.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
syn train_g33_win --scenes 24 --spp 4,16,64,128 --seed 33 --preset windows --sampler stratified \
    --pixel-filter gaussian --filter-width 1.5:4
syn train_g31_sub --scenes 12 --spp 4,16,64,128 --seed 31 --preset exterior --preset organic --preset motion \
    --sampler stratified --pixel-filter gaussian --filter-width 1.5:4
syn train_g30_sub --scenes 12 --spp 16,64,128 --seed 30 --preset easy --preset medium --preset deep-heavy \
    --preset studio --preset thin --preset textured --sampler stratified --pixel-filter gaussian --filter-width 1.5:4
for t in pna5 pna2; do
  trn $t-t1 $V8_POOL $V8_OPTS --steps 1000 --crop 64 --p-no-aux 0.${t#pna}
done
for s in heldout_g1int8_box heldout_g1int8 heldout_g1sg8_boxsob; do
  for spp in 4 16; do
    for kind in noaux base; do
      for t in pna5 pna2; do ev $t red32_${kind}_${spp}_$s $R/cpu-small-pdl-gza-$t-t1; done
    done
  done
done
touch $S/chain4.done
