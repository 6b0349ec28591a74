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
RECIPE="train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub --config cpu-small-pdl-gza
    --steps 1000 --crop 64 --lr 1e-4 --seed 28 --init cpu-small-pdl-gza-v8 --loss-weight alpha=2
    --loss-weight separation=1 --loss-weight flip=2 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2
    --spp-weight 128=2 --rotate-normals 0.5"
for t in pna5 pna2; do
  p=0.${t#pna}
  [ -f $S/$t-t1.done ] || { ( time ranad train $RECIPE --p-no-aux $p -o $R/cpu-small-pdl-gza-$t-t1 ) \
      > $S/train_$t-t1.log 2>&1 && touch $S/$t-t1.done; }
done
for s in heldout_g1int8_box heldout_g1int8 heldout_g1sg8_boxsob; do
  for spp in 4 16; do
    for kind in noaux base; do
      for t in pna5 pna2; do ev $t red32_${kind}_${spp}_$s $R/cpu-small-pdl-gza-$t-t1; done
    done
  done
done
touch $S/chain4.done
