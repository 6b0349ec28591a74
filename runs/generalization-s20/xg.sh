#!/bin/bash
# session 20: export the fine-tuned single-frame model, retrain the cross-frame model on it, export, score sequences
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
W=/work/main/ranad_core/weights
while [ ! -f s20/chain.done ]; do sleep 10; done
( ranad export $R/cpu-small-pdl-gzf-t4 -o $W/cpu-small-pdl-gza-v4.safetensors $(cat s19/halo_frames.txt) ) > $R/cpu-small-pdl-gzf-t4/export.log 2>&1
( time ranad train train_g3 train_g3s -o $R/cpu-small-pdl-gzf-xg-t3 --config cpu-small-pdl-gza-xg \
    --init cpu-small-pdl-gza-v4 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > s20/train_xg3.log 2>&1
( ranad export $R/cpu-small-pdl-gzf-xg-t3 -o $W/cpu-small-pdl-gza-xg-v4.safetensors $(cat s19/halo_frames.txt) ) > $R/cpu-small-pdl-gzf-xg-t3/export.log 2>&1
( time ranad eval heldout_g3s2 -o s20/evT_v4 --temporal --model cpu-small-pdl-gza-v4 --cross-model cpu-small-pdl-gza-xg-v4 ) > s20/evT_v4.log 2>&1
echo done > s20/xg.done
