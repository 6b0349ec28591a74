# The control for chain1.sh at equal pixels: the same fine-tune at crop 64 with four times the steps (c64l: 4000
# steps, so as many pixels as c128-t1's 1000 steps of whole frames), then the six held-out sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RECIPE="train_g35_boxsob --config cpu-small-pdl-gza --lr 1e-4 --seed 28
    --init cpu-small-pdl-gza-v8 --loss-weight alpha=2 --loss-weight separation=1 --loss-weight flip=2
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5"
[ -f $S/c64l-t1.done ] || { ( time ranad train $RECIPE --steps 4000 --crop 64 -o $R/cpu-small-pdl-gza-c64l-t1 ) \
    > $S/train_c64l-t1.log 2>&1 && touch $S/c64l-t1.done; }
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c64l $s $R/cpu-small-pdl-gza-c64l-t1
done
touch $S/chain2.done
