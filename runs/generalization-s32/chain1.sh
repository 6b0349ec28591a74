# Does the training crop's size limit what the kernels learn about wide, smooth regions? Every model so far trained
# on 64x64 crops, where a coarse scale's disc is mostly cut by the crop's border. Session 31's control (ctl-t1: v8
# + 1000 steps of v8's recipe on train_g35_boxsob, crop 64) again with whole 128x128 frames (c128-t1: the same
# recipe, seed and steps, --crop 128: four times the pixels per step), then both on the six held-out sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RECIPE="train_g35_boxsob --config cpu-small-pdl-gza --steps 1000 --lr 1e-4 --seed 28
    --init cpu-small-pdl-gza-v8 --loss-weight alpha=2 --loss-weight separation=1 --loss-weight flip=2
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5"
[ -f $S/c128-t1.done ] || { ( time ranad train $RECIPE --crop 128 -o $R/cpu-small-pdl-gza-c128-t1 ) \
    > $S/train_c128-t1.log 2>&1 && touch $S/c128-t1.done; }
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c128 $s $R/cpu-small-pdl-gza-c128-t1
done
touch $S/chain1.done
