#!/bin/bash
# session 23, second: v6 trained on (3000 more steps, its pool and crop weights) with 80% of the crops' normals turned
# instead of half: does the model get closer to invariant to the normals' space without losing as rendered?
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
while [ ! -f s23/chain1.done ]; do sleep 10; done
[ -f $R/cpu-small-pdl-gzw-t5/train.done ] || { ( time OMP_NUM_THREADS=2 ranad train train_g33_win train_g31_sub \
    train_g31_sub train_g30_sub train_g30_sub -o $R/cpu-small-pdl-gzw-t5 --config cpu-small-pdl-gza --steps 3000 \
    --crop 64 --lr 1e-4 --seed 17 --init cpu-small-pdl-gza-v6 --loss-weight alpha=2 --loss-weight separation=1 \
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.8 ) \
    > s23/train_gzw5.log 2>&1 && touch $R/cpu-small-pdl-gzw-t5/train.done; }
ev() { [ -f s23/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s23/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s23/ev_$1_$2.log 2>&1; }
for s in heldout_g1fog heldout_g1int8 heldout_g1sg8 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot \
         heldout_g1sg8_yaw; do
    ev gzw5 $s $R/cpu-small-pdl-gzw-t5
done
echo done > s23/chain2.done
