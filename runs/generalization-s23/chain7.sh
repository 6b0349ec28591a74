#!/bin/bash
# session 23, seventh: ship the half-way interpolation of v5 and v6 as v7 (measured halo), train the cross-frame
# model on it (xg-v5's recipe), score the pair on the box and Gaussian shots, and v7's exposure sweep
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
W=/work/main/ranad_core/weights
[ -f $W/cpu-small-pdl-gza-v7.safetensors ] || /work/main/runs/generalization-s23/export.sh cpu-small-pdl-gza-v6 \
    $W/cpu-small-pdl-gza-v7.safetensors --interpolate cpu-small-pdl-gza-v5=0.5 > s23/export_v7.log 2>&1
X=$R/cpu-small-pdl-gzm-xg-t1
[ -f $X/train.done ] || { ( time ranad train train_g3 train_g3s -o $X --config cpu-small-pdl-gza-xg \
    --init cpu-small-pdl-gza-v7 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > s23/train_xg7.log 2>&1 \
    && touch $X/train.done; }
[ -f $W/cpu-small-pdl-gza-xg-v7.safetensors ] || /work/main/runs/generalization-s23/export.sh $X \
    $W/cpu-small-pdl-gza-xg-v7.safetensors > s23/export_xg7.log 2>&1
for s in heldout_g3s2 heldout_g3s2g; do
    [ -f s23/evt7_$s/temporal.md ] || ( time ranad eval $s -o s23/evt7_$s --temporal --model cpu-small-pdl-gza-v7 \
        --cross-model cpu-small-pdl-gza-xg-v7 ) > s23/evt7_$s.log 2>&1
done
[ -f s23/evX_v7/eval.md ] || ( time ranad eval heldout_g1sg8 -o s23/evX_v7 --model cpu-small-pdl-gza-v7 \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > s23/evX_v7.log 2>&1
echo done > s23/chain7.done
