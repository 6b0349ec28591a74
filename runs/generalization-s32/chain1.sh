# Does the training crop's size limit what the kernels learn about wide, smooth regions? Every model so far trained
# on 64x64 crops, where a coarse scale's disc is mostly cut by the crop's border. Session 31's control (ctl-t1: v8
# + 1000 steps of v8's recipe on train_g35_boxsob, crop 64) again with whole 128x128 frames (c128-t1: the same
# recipe, seed and steps, --crop 128: four times the pixels per step), then both on the six held-out sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
trn c128-t1 train_g35_boxsob $V8_OPTS --steps 1000 --crop 128
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c128 $s $R/cpu-small-pdl-gza-c128-t1
done
touch $S/chain1.done
