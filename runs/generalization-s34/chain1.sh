#!/bin/bash
# session 34, first: the rest of v8's card's sets for v9 and the cross-frame pair on v9. Rendered again from their
# recipes: Gaussian fog (heldout_g1fog, session 22's chain.sh), width-4 glass and layers (heldout_g1w4, session 22's
# chain5.sh), the turned and yawed copies (session 22's rotate_normals.py), the training shots of xg-v8's recipe
# (train_g3: cpu-small-p-v1.md; train_g3s: session 23's chain1.sh) and the two held-out shot sets (heldout_g3s2,
# heldout_g3s2g: session 23's chain1.sh and chain5.sh). Then xg-v9 by xg-v8's recipe (session 28's chain4.sh) with
# v9's weights frozen, and v9 / v8 and their pairs scored on all of them.
. "$(dirname "$0")/common.sh"
G="--sampler stratified --pixel-filter gaussian"
syn heldout_g1fog --scenes 8 --spp 4,16,64 --seed 1109 --preset fog --filter-width 2 $G
syn heldout_g1w4 --scenes 8 --spp 4,16,64 --ref-spp 512 --seed 1097 --preset glass --preset layers $G \
    --filter-width 4
ROT=$R/generalization-s22/rotate_normals.py
for s in heldout_g1sg8 heldout_g1fog heldout_g1int8; do
    [ -d ${s}_rot ] || python $ROT $s ${s}_rot --seed 0 > $S/rot_$s.log 2>&1 || exit 1
done
[ -d heldout_g1sg8_yaw ] || python $ROT heldout_g1sg8 heldout_g1sg8_yaw --seed 1 --yaw > $S/yaw.log 2>&1 || exit 1
for s in heldout_g1fog heldout_g1w4 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot heldout_g1sg8_yaw; do
    for m in v9 v8; do ev $m $s cpu-small-pdl-gza-$m; done
done
# shots: sequences of 3 frames, box-filtered (the synth default), references on every held-out frame
P="--preset easy --preset medium --preset deep-heavy --preset studio --preset thin --preset textured"
FRAMES=3 syn heldout_g3s2 --scenes 6 --spp 4,16 --seed 1023 --preset glass --preset layers --motion 0.25 \
    --ref-frames all
FRAMES=3 syn heldout_g3s2g --scenes 6 --spp 4,16 --seed 1023 --preset glass --preset layers --motion 0.25 \
    --ref-frames all $G --filter-width 2
FRAMES=3 syn train_g3 --scenes 12 --spp 4,16,64 --seed 3 $P
FRAMES=3 syn train_g3s --scenes 24 --spp 4,16,64 --seed 31 --motion 0.25 $P
xgt 9 $V9 || exit 1
for s in heldout_g3s2 heldout_g3s2g; do
    evt xg9 $s cpu-small-pdl-gza-v9 $S/xg9.safetensors
    evt xg8 $s cpu-small-pdl-gza-v8 cpu-small-pdl-gza-xg-v8
done
touch $S/chain1.done
