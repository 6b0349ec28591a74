# session 29, chain 3: the rest of cpu-small-pdl-gza-v8's card rows with light matching (normals turned, yawed,
# 1 / 2 / 128 spp, the in-family Sobol set) and its exposure sweep (session 28's s28/ev_v8_* without it)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
ev_sets lm8 cpu-small-pdl-gza-v8 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot heldout_g1sg8_yaw heldout_g1sp \
    infam_g36_boxsob
[ -f $S/ev_lm8x_heldout_g1sg8/eval.md ] || ( time ranad eval heldout_g1sg8 -o $S/ev_lm8x_heldout_g1sg8 \
    --model cpu-small-pdl-gza-v8 --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) \
    > $S/ev_lm8x_heldout_g1sg8.log 2>&1
