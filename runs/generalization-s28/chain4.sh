#!/bin/bash
# session 28: the shipped pair from the chosen single-frame weights CAND (a run or .safetensors): exported with v6's
# halo frames (generalization-s23/export.sh), the cross-frame model rebuilt on it by the xg-v7 recipe (spatial
# weights frozen), and the card's remaining sets: normals turned, yawed, 1/2/128 spp, in-family, shots, exposure sweep
# usage: chain4.sh CAND [EXPORT OPTIONS]     (run from anywhere; data in /work/data); session 28 ran
#   chain4.sh /work/main/runs/cpu-small-pdl-gza-fl-t1 --interpolate cpu-small-pdl-gza-v7=0.5
. "$(dirname "$0")/common.sh"
CAND=$1
[ -f $S/v8.safetensors ] || bash $R/generalization-s23/export.sh $CAND $S/v8.safetensors "${@:2}" \
    > $S/export_v8.log 2>&1 || exit 1
[ -f $R/cpu-small-pdl-gza-xg-t8/checkpoint.pt ] || ( time OMP_NUM_THREADS=2 ranad train train_g3 train_g3s \
    -o $R/cpu-small-pdl-gza-xg-t8 --config cpu-small-pdl-gza-xg --init $S/v8.safetensors --window 3 --steps 800 \
    --crop 64 --lr 5e-4 --seed 0 --freeze-spatial --loss-weight alpha=2 --loss-weight separation=1 \
    --checkpoint-every 100 ) > $S/train_xg8.log 2>&1 || exit 1
[ -f $S/xg8.safetensors ] || bash $R/generalization-s23/export.sh $R/cpu-small-pdl-gza-xg-t8 $S/xg8.safetensors \
    > $S/export_xg8.log 2>&1 || exit 1
for s in heldout_g1sg8_rot heldout_g1int8_rot heldout_g1fog_rot heldout_g1sg8_yaw heldout_g1sp infam_g36_box \
    infam_g36_boxsob; do
    ev v8 $s $S/v8.safetensors
done
for s in heldout_g3s2 heldout_g3s2g; do
    [ -f $S/evt8_$s/temporal.md ] || ( time ranad eval $s -o $S/evt8_$s --temporal --model $S/v8.safetensors \
        --cross-model $S/xg8.safetensors ) > $S/evt8_$s.log 2>&1
done
[ -f $S/evx8/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/evx8 --model $S/v8.safetensors \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > $S/evx8.log 2>&1
touch $S/chain4.done
