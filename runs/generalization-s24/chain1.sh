#!/bin/bash
# session 24, first: the cross-frame step trained on Gaussian-filtered shots too. xg-v7's temporal step saw box-filtered
# shots only (train_g3, train_g3s) and gains nothing over its single frame through a Gaussian (its card); production
# renderers filter with Gaussians. train_g3sg: train_g3s's recipe (12 scenes, a new seed) with stratified samples
# through a Gaussian of width 1.5-4 (v6's pool's film); then xg-v7's recipe on all three sets, scored on both shot sets.
. /work/main/runs/generalization-s24/common.sh
R=/work/main/runs
[ -f s24/train_g3sg.done ] || { ( time ranad synth -o train_g3sg --scenes 12 --size 128 --frames 3 --spp 4,16,64 \
    --ref-spp 1024 --seed 34 --workers 2 --motion 0.25 --preset easy --preset medium --preset deep-heavy \
    --preset studio --preset thin --preset textured --sampler stratified --pixel-filter gaussian \
    --filter-width 1.5:4 ) > s24/synth_train_g3sg.log 2>&1 && touch s24/train_g3sg.done; }
X=$R/cpu-small-pdl-gzm-xg-t2
[ -f $X/train.done ] || { ( time ranad train train_g3 train_g3s train_g3sg -o $X --config cpu-small-pdl-gza-xg \
    --init cpu-small-pdl-gza-v7 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > s24/train_xg_t2.log 2>&1 \
    && touch $X/train.done; }
for s in heldout_g3s2g heldout_g3s2; do
    [ -f s24/evt_t2_$s/temporal.md ] || ( time ranad eval $s -o s24/evt_t2_$s --temporal \
        --model cpu-small-pdl-gza-v7 --cross-model $X ) > s24/evt_t2_$s.log 2>&1
done
echo done > s24/chain1.done
