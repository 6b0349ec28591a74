#!/bin/bash
# session 27: box-filtered, Sobol-sampled scenes of the training families (flat OIDN's own conditions, where v7 loses
# to it on held-out interiors), v7 fine-tuned on them pooled with v6's data (t16), scored on the box and the
# Gaussian held-out sets
. "$(dirname "$0")/common.sh"
syn train_g35_boxsob --scenes 24 --spp 4,16,64,128 --seed 35 --preset easy --preset medium --preset deep-heavy \
    --preset studio --preset thin --preset textured --preset exterior --preset organic --preset motion \
    --preset windows --sampler sobol --pixel-filter box
[ -f s27/train_g35_boxsob.done ] && python $R/generalization-s21/check_finite.py train_g35_boxsob \
    > s27/finite_g35.log 2>&1 || exit 1
( time OMP_NUM_THREADS=2 ranad train train_g35_boxsob train_g35_boxsob train_g33_win train_g31_sub train_g30_sub \
    -o $R/cpu-small-pdl-gzb-t16 --config cpu-small-pdl-gza --steps 2000 --crop 64 --lr 5e-5 --seed 28 \
    --init cpu-small-pdl-gza-v7 --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
    --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) >> s27/train_t16.log 2>&1
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1fog_boxsob heldout_g1sg8_boxsob heldout_g1int8 \
    heldout_g1sg8 heldout_g1w4 heldout_g1ac8 heldout_g1fog; do
    ev t16 $s $R/cpu-small-pdl-gzb-t16
done
touch s27/chain4.done
