#!/bin/bash
# session 21: v4 fine-tuned with sky-lit (exterior), mesh (organic) and motion-blurred scenes (train_g31_new, listed
# twice: drawn twice as often as a scene of the older sets); then scored on every held-out set
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
W=/work/main/ranad_core/weights
while pgrep -f "synth -o train_g31_new" > /dev/null; do sleep 10; done
( time ranad synth -o train_g31_new --scenes 36 --size 128 --frames 1 --spp 4,16,64,128 --ref-spp 1024 --seed 31 \
    --workers 2 --preset exterior --preset organic --preset motion --sampler stratified --pixel-filter gaussian \
    --filter-width 1.5:4 ) > s21/synth_g31_finish.log 2>&1
python /work/main/runs/generalization-s21/check_finite.py train_g31_new > s21/finite.log 2>&1 || exit 1
( time OMP_NUM_THREADS=2 ranad train train_g8 train_g18_gauss train_g28_gauss train_g29_sg train_g30_hi \
    train_g31_new train_g31_new -o $R/cpu-small-pdl-gzf-t5 --config cpu-small-pdl-gza --steps 2400 --crop 64 \
    --lr 1e-4 --seed 13 --init $R/cpu-small-pdl-gzf-t4 --loss-weight alpha=2 --loss-weight separation=1 \
    --checkpoint-every 200 --spp-weight 64=2 --spp-weight 128=4 ) > s21/train_gzf5.log 2>&1
ev() { [ -f s21/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s21/ev_$1_$2 $3 --held-out glass,layers,interior,fog \
    --grid 0 ) > s21/ev_$1_$2.log 2>&1; }
for s in heldout_g1fog heldout_g1int heldout_g1sg heldout_g1w4 heldout_g1ab_gauss3 heldout_g1ac_gauss heldout_g1ac \
         heldout_g1sp heldout_g1org heldout_g1mot heldout_g1ext infam_g2; do
    ev gzf5 $s "--model $R/cpu-small-pdl-gzf-t5"
done
echo done > s21/chain.done
( ranad export $R/cpu-small-pdl-gzf-t5 -o $W/cpu-small-pdl-gza-v5.safetensors $(cat s19/halo_frames.txt) ) \
    > s21/export_v5.log 2>&1
( time ranad train train_g3 train_g3s -o $R/cpu-small-pdl-gzf-xg-t4 --config cpu-small-pdl-gza-xg \
    --init cpu-small-pdl-gza-v5 --window 3 --steps 800 --crop 64 --lr 5e-4 --seed 0 --freeze-spatial \
    --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 100 ) > s21/train_xg4.log 2>&1
( ranad export $R/cpu-small-pdl-gzf-xg-t4 -o $W/cpu-small-pdl-gza-xg-v5.safetensors $(cat s19/halo_frames.txt) ) \
    > s21/export_xg5.log 2>&1
( time ranad eval heldout_g3s2 -o s21/evT_v5 --temporal --model cpu-small-pdl-gza-v5 \
    --cross-model cpu-small-pdl-gza-xg-v5 ) > s21/evT_v5.log 2>&1
echo done > s21/xg.done
