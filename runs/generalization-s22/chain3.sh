#!/bin/bash
# session 22, third run: --rotate-normals 0.5 again, 3000 steps, the two regenerated subsets of v5's data listed twice
# (a third of the crops from `windows`, half in gzw1/gzw2), to keep more of v5 on its own families
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
while [ ! -f s22/chain2.done ]; do sleep 10; done
( time OMP_NUM_THREADS=2 ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R/cpu-small-pdl-gzw-t3 --config cpu-small-pdl-gza --steps 3000 --crop 64 --lr 1e-4 --seed 15 \
    --init cpu-small-pdl-gza-v5 --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
    --spp-weight 64=2 --spp-weight 128=4 --rotate-normals 0.5 ) > s22/train_gzw3.log 2>&1
ev() { [ -f s22/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s22/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s22/ev_$1_$2.log 2>&1; }
for s in heldout_g1fog heldout_g1int8 heldout_g1sg8 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot \
         heldout_g1sg8_yaw; do
    ev gzw3 $s $R/cpu-small-pdl-gzw-t3
done
echo done > s22/chain3.done
