#!/bin/bash
# session 27: training scenes of the training families rendered with `--sampler sobol`, v7 fine-tuned on them
# pooled with v6's data (t15), then scored on the held-out sets as rendered (stratified) and with Sobol samples
. "$(dirname "$0")/common.sh"
syn train_g34_sob --scenes 30 --spp 4,16,64,128 --seed 34 --preset easy --preset medium --preset deep-heavy \
    --preset studio --preset thin --preset textured --preset exterior --preset organic --preset motion \
    --preset windows --sampler sobol --pixel-filter gaussian --filter-width 1.5:4
[ -f s27/train_g34_sob.done ] && python $R/generalization-s21/check_finite.py train_g34_sob \
    > s27/finite_g34.log 2>&1 || exit 1
( time OMP_NUM_THREADS=2 ranad train train_g34_sob train_g34_sob \
    train_g33_win train_g31_sub train_g30_sub -o $R/cpu-small-pdl-gzs-t15 --config cpu-small-pdl-gza --steps 2000 \
    --crop 64 --lr 5e-5 --seed 27 --init cpu-small-pdl-gza-v7 --loss-weight alpha=2 --loss-weight separation=1 \
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) \
    >> s27/train_t15.log 2>&1
for s in heldout_g1sg8_sob heldout_g1int8_sob heldout_g1fog_sob heldout_g1w4 heldout_g1sg8 heldout_g1ac8 \
    heldout_g1int8 heldout_g1fog heldout_g1sp; do
    ev t15 $s $R/cpu-small-pdl-gzs-t15
done
touch s27/chain2.done
