# Fine-tuning with OIDN's prefiltered aux in the flat prior (cp-t1) against the same fine-tune on the raw aux
# (ctl-t1): v8's recipe (fl-t1's, its card) from v8's weights, cut to fit the session: 1000 steps on the
# box-filtered, Sobol-sampled set of the training families alone (its other sets took 105 s a scene to render
# beside the evaluations, and were stopped); then both on chain1.sh's held-out sets, cp-t1 with the prefiltered
# prior at inference too
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
syn_train() { [ -f $S/$1.done ] || { ( time ranad synth -o $1 --size 128 --frames 1 --ref-spp 1024 --workers 2 \
    "${@:2}" ) > $S/synth_$1.log 2>&1 && touch $S/$1.done; }; }
syn_train train_g35_boxsob --scenes 24 --spp 4,16,64,128 --seed 35 --preset easy --preset medium \
    --preset deep-heavy --preset studio --preset thin --preset textured --preset exterior --preset organic \
    --preset motion --preset windows --sampler sobol --pixel-filter box
RECIPE="train_g35_boxsob --config cpu-small-pdl-gza --steps 1000 --crop 64 --lr 1e-4 --seed 28
    --init cpu-small-pdl-gza-v8 --loss-weight alpha=2 --loss-weight separation=1 --loss-weight flip=2
    --checkpoint-every 200 --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5"
[ -f $S/cp-t1.done ] || { ( time python $R/generalization-s31/clean_aux.py --command train \
    --where prior $RECIPE -o $R/cpu-small-pdl-gza-cp-t1 ) > $S/train_cp-t1.log 2>&1 && touch $S/cp-t1.done; }
[ -f $S/ctl-t1.done ] || { ( time ranad train $RECIPE -o $R/cpu-small-pdl-gza-ctl-t1 ) \
    > $S/train_ctl-t1.log 2>&1 && touch $S/ctl-t1.done; }
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1sg8_boxsob heldout_g1fog_boxsob heldout_g1int8 \
         heldout_g1sg8; do
  while [ ! -f $S/$s.done ]; do sleep 20; done
  ev ctl $s $R/cpu-small-pdl-gza-ctl-t1
  evc prior cpt $s $R/cpu-small-pdl-gza-cp-t1
done
touch $S/chain2.done
