# The control for chain1.sh at equal pixels: the same fine-tune at crop 64 with four times the steps (c64l: 4000
# steps, so as many pixels as c128-t1's 1000 steps of whole frames), then the six held-out sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
trn c64l-t1 train_g35_boxsob $V8_OPTS --steps 4000 --crop 64
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c64l $s $R/cpu-small-pdl-gza-c64l-t1
done
touch $S/chain2.done
