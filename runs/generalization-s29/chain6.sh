# session 29, chain 6: the default with light matching to the noisy render's own light (33x33, within 2%; section 5)
# scored as chains 1-3 scored the first version (tag ln16; lm8 and evt8lm are the first version's folders)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
ev_sets ln16 cpu-small-pdl-gza-v8 $HELDOUT9 infam_g36_box heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot \
    heldout_g1sg8_yaw heldout_g1sp infam_g36_boxsob
for s in heldout_g3s2 heldout_g3s2g; do
    [ -f $S/evtln16_$s/temporal.md ] || ( time ranad eval $s -o $S/evtln16_$s --temporal --model cpu-small-pdl-gza-v8 \
        --cross-model cpu-small-pdl-gza-xg-v8 ) > $S/evtln16_$s.log 2>&1
done
[ -f $S/ev_ln16x_heldout_g1sg8/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/ev_ln16x_heldout_g1sg8 \
    --model cpu-small-pdl-gza-v8 --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) \
    > $S/ev_ln16x_heldout_g1sg8.log 2>&1
[ -f $S/headline_ln16.log ] || ( time ranad denoise /work/main/examples/synth_shot/noisy_spp16.####.exr \
    -o $S/headline_ln16/beauty.####.exr --reference /work/main/examples/synth_shot/reference_spp16.####.exr ) \
    > $S/headline_ln16.log 2>&1
