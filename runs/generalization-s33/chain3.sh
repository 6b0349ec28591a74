# chain1.sh's crop-64 fine-tune with as many pixels as its whole-frame one (c64f4-t1: v8 + 4000 steps of v8's recipe
# on its whole pool at --crop 64, the schedule over 4000 steps), scored on the same six held-out sets: whole frames
# against more crops for the same pixels, on the pool (session 32 asked it on one set of it).
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
RECIPE="train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub --config cpu-small-pdl-gza
    --steps 4000 --lr 1e-4 --seed 28 --init cpu-small-pdl-gza-v8 --loss-weight alpha=2
    --loss-weight separation=1 --loss-weight flip=2 --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2
    --spp-weight 128=2 --rotate-normals 0.5"
[ -f $S/c64f4-t1.done ] || { ( time ranad train $RECIPE --crop 64 -o $R/cpu-small-pdl-gza-c64f4-t1 ) \
    > $S/train_c64f4-t1.log 2>&1 && touch $S/c64f4-t1.done; }
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1int8 heldout_g1fog_boxsob heldout_g1sg8_boxsob \
         heldout_g1sg8; do
  ev c64f4 $s $R/cpu-small-pdl-gza-c64f4-t1
done
touch $S/chain3.done
