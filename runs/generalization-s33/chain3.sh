# chain1.sh's crop-64 fine-tune with as many pixels as its whole-frame one (c64f4-t1: v8 + 4000 steps of v8's recipe
# on its whole pool at --crop 64, the schedule over 4000 steps), scored on the same six held-out sets: whole frames
# against more crops for the same pixels, on the pool (session 32 asked it on one set of it).
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
trn c64f4-t1 $V8_POOL $V8_OPTS --steps 4000 --crop 64
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c64f4 $s $R/cpu-small-pdl-gza-c64f4-t1
done
touch $S/chain3.done
