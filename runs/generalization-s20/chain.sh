#!/bin/bash
# session 20: v3 fine-tuned with 128-spp data (train_g30_hi); held-out sky-lit (exterior), mesh (organic), fog and motion-blur sets;
# evaluations
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
HO=glass,layers,interior,exterior,organic,fog,motion
while pgrep -f "synth -o train_g30_hi" > /dev/null; do sleep 10; done
( time ranad synth -o train_g30_hi --scenes 48 --size 128 --frames 1 --spp 16,64,128 --ref-spp 1024 --seed 30 \
    --workers 2 --preset easy --preset medium --preset deep-heavy --preset studio --preset thin --preset textured \
    --sampler stratified --pixel-filter gaussian --filter-width 1.5:4 ) > s20/synth_g30_finish.log 2>&1
( time OMP_NUM_THREADS=2 ranad train train_g8 train_g18_gauss train_g28_gauss train_g29_sg train_g30_hi \
    -o $R/cpu-small-pdl-gzf-t4 --config cpu-small-pdl-gza --steps 2400 --crop 64 --lr 1e-4 --seed 12 \
    --init $R/cpu-small-pdl-gzf-t3 --loss-weight alpha=2 --loss-weight separation=1 --checkpoint-every 200 \
    --spp-weight 64=2 --spp-weight 128=4 ) > s20/train_gzf4.log 2>&1
ev() { [ -f s20/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s20/ev_$1_$2 $3 --held-out $HO --grid 0 ) > s20/ev_$1_$2.log 2>&1; }
ev gzf4 heldout_g1sp "--model $R/cpu-small-pdl-gzf-t4"
( time ranad synth -o heldout_g1ext --scenes 8 --size 128 --frames 1 --spp 4,16,64 --ref-spp 1024 --seed 1105 \
    --workers 2 --preset exterior --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s20/synth_ext.log 2>&1
( time ranad synth -o heldout_g1org --scenes 8 --size 128 --frames 1 --spp 4,16,64 --ref-spp 1024 --seed 1107 \
    --workers 2 --preset organic --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s20/synth_org.log 2>&1
( time ranad synth -o heldout_g1fog --scenes 8 --size 128 --frames 1 --spp 4,16,64 --ref-spp 1024 --seed 1109 \
    --workers 2 --preset fog --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s20/synth_fog.log 2>&1
( time ranad synth -o heldout_g1mot --scenes 8 --size 128 --frames 1 --spp 4,16,64 --ref-spp 1024 --seed 1111 \
    --workers 2 --preset motion --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s20/synth_mot.log 2>&1
ev v3 heldout_g1ext "--model cpu-small-pdl-gza-v3"
ev gzf4 heldout_g1ext "--model $R/cpu-small-pdl-gzf-t4"
ev v3 heldout_g1org "--model cpu-small-pdl-gza-v3"
ev gzf4 heldout_g1org "--model $R/cpu-small-pdl-gzf-t4"
ev v3 heldout_g1fog "--model cpu-small-pdl-gza-v3"
ev gzf4 heldout_g1fog "--model $R/cpu-small-pdl-gzf-t4"
ev v3 heldout_g1mot "--model cpu-small-pdl-gza-v3"
ev gzf4 heldout_g1mot "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 heldout_g1int "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 heldout_g1sg "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 infam_g2 "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 heldout_g1w4 "--model $R/cpu-small-pdl-gzf-t4"
echo done > s20/chain.done
