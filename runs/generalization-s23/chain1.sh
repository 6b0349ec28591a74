#!/bin/bash
# session 23: the cross-frame default retrained on the single-frame v6 (cpu-small-pdl-gza-xg-v5's recipe), its data
# rendered again from the seeds in cpu-small-p-v1.md / cpu-small-pd-xg-v1.md, then scored beside the v5 pair
cd /work/data
. /work/main/.venv/bin/activate
P="--preset easy --preset medium --preset deep-heavy --preset studio --preset thin --preset textured"
[ -f s23/train_g3s.done ] || { ( time ranad synth -o train_g3s --scenes 24 --size 128 --frames 3 --spp 4,16,64 \
    --ref-spp 1024 --seed 31 --workers 2 --motion 0.25 $P ) > s23/synth_train_g3s.log 2>&1 && touch s23/train_g3s.done; }
[ -f s23/heldout_g3s2.done ] || { ( time ranad synth -o heldout_g3s2 --scenes 6 --size 128 --frames 3 --spp 4,16 \
    --ref-spp 1024 --seed 1023 --workers 2 --preset glass --preset layers --motion 0.25 --ref-frames all ) \
    > s23/synth_heldout_g3s2.log 2>&1 && touch s23/heldout_g3s2.done; }
R=/work/main/runs/cpu-small-pdl-gzw-xg-t1
[ -f $R/train.done ] || { ( time ranad train train_g3 train_g3s -o $R --config cpu-small-pdl-gza-xg \
    --init cpu-small-pdl-gza-v6 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > $R.train.log 2>&1 \
    && touch $R/train.done; }
[ -f s23/xg6.safetensors ] || ranad export $R -o s23/xg6.safetensors > s23/export_xg6.log 2>&1
[ -f s23/evt_v5/eval.md ] || ( time ranad eval heldout_g3s2 -o s23/evt_v5 --temporal --model cpu-small-pdl-gza-v5 \
    --cross-model cpu-small-pdl-gza-xg-v5 ) > s23/evt_v5.log 2>&1
[ -f s23/evt_v6/eval.md ] || ( time ranad eval heldout_g3s2 -o s23/evt_v6 --temporal --model cpu-small-pdl-gza-v6 \
    --cross-model s23/xg6.safetensors ) > s23/evt_v6.log 2>&1
echo done > s23/chain1.done
