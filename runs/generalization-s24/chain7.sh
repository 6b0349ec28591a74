#!/bin/bash
# session 24, seventh: is the specular blur at low noise learned on the training scenes too? v7 on the first 8
# scenes of its own windows family (seen in training: in-family), deep-Z, 16 / 64 / 128 spp, against the noisy input.
. /work/main/runs/generalization-s24/common.sh
[ -f s24/ev_v7_train_g33_win/eval.md ] || ( time ranad eval train_g33_win -o s24/ev_v7_train_g33_win \
    --model cpu-small-pdl-gza-v7 --scenes 8 --kind deepz --spp 16,64,128 --grid 0 ) > s24/ev_v7_train_g33_win.log 2>&1
for l in specular; do
    [ -f s24/ev_v7keep_${l}_train_g33_win/eval.md ] || ( time python \
        /work/main/runs/generalization-s24/ev_keep_layer.py $l train_g33_win -o s24/ev_v7keep_${l}_train_g33_win \
        --model cpu-small-pdl-gza-v7 --scenes 8 --kind deepz --spp 16,64,128 --grid 0 ) \
        > s24/ev_v7keep_${l}_train_g33_win.log 2>&1
done
echo done > s24/chain7.done
