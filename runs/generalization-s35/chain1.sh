#!/bin/bash
# session 35: the pool itself. v8's pool holds 72 scenes: 24 box-filtered Sobol ones (listed twice) and 48
# Gaussian-filtered ones. Session 34's v10 ran another 3000 steps of v9's recipe on that pool and gained a third of a
# percent; this chain runs the same 3000 steps (same seed, same options) on twice as many scenes of the same
# training families, every scene listed once and the two filters in equal parts: 48 new box-filtered Sobol scenes
# and 24 new Gaussian-filtered stratified ones (new seeds; the Gaussian renders take a minute a scene here, so 24 rather
# than 48), 144 in all. Scored on every held-out set of v9's card and session 34's, in-family, the exposure sweep;
# then a cross-frame model on it by xg-v8's recipe, on the two shot sets. (Stopped after the in-family sets: the
# result was not to be shipped, so its cross-frame model, shots and exposure sweep did not run.)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
syn train_g40_boxsob --scenes 48 --spp 4,16,64,128 --seed 40 $FAMILIES --sampler sobol --pixel-filter box || exit 1
syn train_g41_gauss --scenes 24 --spp 4,16,64,128 --seed 41 $FAMILIES --sampler stratified --pixel-filter gaussian \
    --filter-width 1.5:4 || exit 1
for d in train_g40_boxsob train_g41_gauss; do
    [ -f $S/finite_$d.log ] || python $R/generalization-s21/check_finite.py $d > $S/finite_$d.log 2>&1 || exit 1
done
C=$R/cpu-small-pdl-gza-c128p2-t1
P2_POOL="train_g35_boxsob train_g40_boxsob train_g33_win train_g31_sub train_g30_sub train_g41_gauss"
trn c128p2-t1 $P2_POOL $V8_OPTS --steps 3000 --crop 128 --init $V9 --seed 34 || exit 1
[ -f $S/p2.safetensors ] || bash $R/generalization-s23/export.sh $C $S/p2.safetensors > $S/export_p2.log 2>&1 \
    || exit 1
for s in $SETS; do ev p2 $s $S/p2.safetensors; done
xgt p2 $S/p2.safetensors || exit 1
for s in heldout_g3s2 heldout_g3s2g; do evt xgp2 $s $S/p2.safetensors $S/xgp2.safetensors; done
[ -f $S/evxp2/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/evxp2 --model $S/p2.safetensors \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > $S/evxp2.log 2>&1
touch $S/chain1.done
