#!/bin/bash
# session 22, fourth run: gzw3 with 4-spp crops drawn twice as often and 128-spp ones twice instead of four times
# (gzw2/gzw3 lost 1.5-3.5% at 4 spp, where this pool has fewer 4-spp crops than v5's), then issue 27's benches
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
while [ ! -f s22/chain3.done ]; do sleep 10; done
( time OMP_NUM_THREADS=2 ranad train train_g33_win train_g31_sub train_g31_sub train_g30_sub train_g30_sub \
    -o $R/cpu-small-pdl-gzw-t4 --config cpu-small-pdl-gza --steps 3000 --crop 64 --lr 1e-4 --seed 16 \
    --init cpu-small-pdl-gza-v5 --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
    --spp-weight 4=2 --spp-weight 64=2 --spp-weight 128=2 --rotate-normals 0.5 ) > s22/train_gzw4.log 2>&1
ev() { [ -f s22/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s22/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s22/ev_$1_$2.log 2>&1; }
for s in heldout_g1fog heldout_g1int8 heldout_g1sg8 heldout_g1fog_rot heldout_g1int8_rot heldout_g1sg8_rot \
         heldout_g1sg8_yaw; do
    ev gzw4 $s $R/cpu-small-pdl-gzw-t4
done
[ -f s22/evX_gzw4/eval.md ] || ( time ranad eval heldout_g1sg8 -o s22/evX_gzw4 --model $R/cpu-small-pdl-gzw-t4 \
    --held-out glass,layers,interior,fog --grid 0 --kind deepz --exposure -6,0,6 ) > s22/evX_gzw4.log 2>&1
echo done > s22/chain4.done
# issue 27's figures on this machine (AVX-512), nothing else running
cd /work/main
python bench/denoise.py --real "" --frame /work/data/heldout_g1_s5/scene_0005/deepz/noisy_spp16.0000.exr \
    > /work/data/s22/bench_heldout.log 2>&1
python bench/rana.py --threads 2 > /work/data/s22/bench_rana.log 2>&1
echo done > /work/data/s22/bench.done
