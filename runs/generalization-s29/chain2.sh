# session 29, chain 2: the shot pair (cpu-small-pdl-gza-v8, cpu-small-pdl-gza-xg-v8) with light matching on the
# two held-out shot sets of their cards (session 28's s28/evt8_* are the same pair without it)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
for s in heldout_g3s2 heldout_g3s2g; do
    [ -f $S/evt8lm_$s/temporal.md ] || ( time ranad eval $s -o $S/evt8lm_$s --temporal --model cpu-small-pdl-gza-v8 \
        --cross-model cpu-small-pdl-gza-xg-v8 ) > $S/evt8lm_$s.log 2>&1
done
# the README's headline command on the bundled shot (flattened SMAPE of the centre frame, before and after)
[ -f $S/headline.log ] || ( time ranad denoise /work/main/examples/synth_shot/noisy_spp16.####.exr \
    -o $S/headline/beauty.####.exr --reference /work/main/examples/synth_shot/reference_spp16.####.exr ) \
    > $S/headline.log 2>&1
