#!/bin/bash
# session 20: heldout_g1mot stopped at 3 scenes (an int64 overflow in the motion-blur seeding, fixed in b27f57c):
# finish it with the same command and score it again
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
HO=glass,layers,interior,exterior,organic,fog,motion
while [ ! -f s20/after.done ]; do sleep 10; done
rm -rf s20/ev_v3_heldout_g1mot s20/ev_gzf4_heldout_g1mot
( time ranad synth -o heldout_g1mot --scenes 8 --size 128 --frames 1 --spp 4,16,64 --ref-spp 1024 --seed 1111 \
    --workers 2 --preset motion --sampler stratified --pixel-filter gaussian --filter-width 2 ) > s20/synth_mot2.log 2>&1
ev() { [ -f s20/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s20/ev_$1_$2 $3 --held-out $HO --grid 0 ) > s20/ev_$1_$2.log 2>&1; }
ev v3 heldout_g1mot "--model cpu-small-pdl-gza-v3"
ev gzf4 heldout_g1mot "--model $R/cpu-small-pdl-gzf-t4"
echo done > s20/fixmot.done
