#!/bin/bash
# session 21, issue 27: the one-U-Net architecture (cpu-small-pdl-gza-u1) from the fine-tuned two-U-Net model,
# the same data and recipe; scored on the held-out sets and timed on the 1080p bench frame
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
while [ ! -f s21/xg.done ]; do sleep 10; done
( time OMP_NUM_THREADS=2 ranad train train_g8 train_g18_gauss train_g28_gauss train_g29_sg train_g30_hi \
    train_g31_new train_g31_new -o $R/cpu-small-pdl-gzu1-t1 --config cpu-small-pdl-gza-u1 --steps 2400 --crop 64 \
    --lr 1e-4 --seed 14 --init $R/cpu-small-pdl-gzf-t5 --loss-weight alpha=2 --loss-weight separation=1 \
    --checkpoint-every 200 --spp-weight 64=2 --spp-weight 128=4 ) > s21/train_u1.log 2>&1
( ranad export $R/cpu-small-pdl-gzu1-t1 -o s21/u1.safetensors $(cat s19/halo_frames.txt) ) > s21/export_u1.log 2>&1
( cd /work/main && python bench/denoise.py --real "" \
    --frame /work/data/heldout_g1/scene_0005/deepz/noisy_spp16.0000.exr \
    --model /work/data/s21/u1.safetensors ) > s21/bench_u1.log 2>&1
( cd /work/main && python bench/denoise.py --real "" \
    --frame /work/data/heldout_g1/scene_0005/deepz/noisy_spp16.0000.exr \
    --model cpu-small-pdl-gza-v5 ) > s21/bench_v5.log 2>&1
ev() { [ -f s21/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s21/ev_$1_$2 $3 --held-out glass,layers,interior,fog \
    --grid 0 ) > s21/ev_$1_$2.log 2>&1; }
for s in heldout_g1fog heldout_g1int heldout_g1sg heldout_g1w4 heldout_g1org heldout_g1mot heldout_g1ext; do
    ev u1 $s "--model s21/u1.safetensors"
done
echo done > s21/u1.done
