# chain1.sh's whole-frame fine-tune three times as long (c128f3-t1: v8 + 3000 steps of v8's recipe on its whole pool
# at --crop 128, the schedule over 3000 steps), scored on the same six held-out sets.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
trn c128f3-t1 $V8_POOL $V8_OPTS --steps 3000 --crop 128
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c128f3 $s $R/cpu-small-pdl-gza-c128f3-t1
done
touch $S/chain2.done
