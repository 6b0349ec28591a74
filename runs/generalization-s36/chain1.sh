#!/bin/bash
# session 36: the walls-and-bounce-light axis. Session 35 doubled the training families' scenes (p2: v8's pool plus
# train_g40_boxsob and train_g41_gauss) and gained in-family, not held-out. No training family draws walls or bounce
# light, the one axis of the held-out interiors (where the done-when fails flat). This chain renders train_g40_boxsob's
# 48 scenes again with `--enclosure 1` (the same seed and options: the same objects, camera and lights, each scene
# inside a room of its own, its lights moved in and some aimed at the walls), trains p2's run with that set in place of
# train_g40_boxsob (same steps, seed, options, init), and scores it on the same sets: the one difference from p2 is
# the rooms around a third of the pool.
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
syn train_g42_enc --scenes 48 --spp 4,16,64,128 --seed 40 $FAMILIES --sampler sobol --pixel-filter box \
    --enclosure 1 || exit 1
[ -f $S/finite_train_g42_enc.log ] || python $R/generalization-s21/check_finite.py train_g42_enc \
    > $S/finite_train_g42_enc.log 2>&1 || exit 1
C=$R/cpu-small-pdl-gza-c128e1-t1
E1_POOL="train_g35_boxsob train_g42_enc train_g33_win train_g31_sub train_g30_sub train_g41_gauss"
trn c128e1-t1 $E1_POOL $V8_OPTS --steps 3000 --crop 128 --init $V9 --seed 34 || exit 1
[ -f $S/e1.safetensors ] || bash $R/generalization-s23/export.sh $C $S/e1.safetensors > $S/export_e1.log 2>&1 \
    || exit 1
for s in $SETS; do ev e1 $s $S/e1.safetensors; done
touch $S/chain1.done
