#!/bin/bash
# session 20: the remaining sets of the v3 card, scored with the fine-tuned model
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
HO=glass,layers,interior,exterior,organic,fog,motion
while [ ! -f s20/xg.done ]; do sleep 10; done
ev() { [ -f s20/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s20/ev_$1_$2 $3 --held-out $HO --grid 0 ) > s20/ev_$1_$2.log 2>&1; }
ev gzf4 heldout_g1ac "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 heldout_g1ab_gauss3 "--model $R/cpu-small-pdl-gzf-t4"
ev gzf4 heldout_g1ac_gauss "--model $R/cpu-small-pdl-gzf-t4"
echo done > s20/after.done
