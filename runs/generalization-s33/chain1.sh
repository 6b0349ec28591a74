# Whole 128x128 training frames on v8's whole pool. Session 32 measured --crop 128 against --crop 64 on one set of the
# pool (train_g35_boxsob), about 0.7% better on the box-filtered interiors. Here the same on the pool v8 was trained
# on: v8 + 1000 steps of its recipe at --crop 128 (c128f-t1) against the same at --crop 64 (c64f-t1: session 32's
# pna2-t1 trained again, whose checkpoint was not kept), both scored on the six held-out sets of session 32.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
trn c128f-t1 $V8_POOL $V8_OPTS --steps 1000 --crop 128
trn c64f-t1 $V8_POOL $V8_OPTS --steps 1000 --crop 64
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c128f $s $R/cpu-small-pdl-gza-c128f-t1
  ev c64f $s $R/cpu-small-pdl-gza-c64f-t1
done
touch $S/chain1.done
