#!/bin/bash
# session 22, second run: the windows fine-tune again with --rotate-normals 0.5 (runs/cpu-small-pdl-gzw-t2, started
# by hand beside this script), then v5, gzw1 and gzw2 on the held-out subsets as rendered and with their normals
# turned (rotate_normals.py: a random rotation per scene, seed 0; `_yaw`: about the vertical only, seed 1)
# The turned copies, made by hand before this script:
#   python rotate_normals.py heldout_g1sg8 heldout_g1sg8_rot --seed 0 (the same for heldout_g1fog, heldout_g1int8)
#   python rotate_normals.py heldout_g1sg8 heldout_g1sg8_yaw --seed 1 --yaw
#   ranad eval heldout_g1sg8_rot -o s22/ev_v5_heldout_g1sg8_rot --model cpu-small-pdl-gza-v5 \
#       --held-out glass,layers,interior,fog --grid 0
cd /work/data
. /work/main/.venv/bin/activate
R=/work/main/runs
while pgrep -f "o /work/main/runs/cpu-small-pdl-gzw-t2" > /dev/null; do sleep 10; done
ev() { [ -f s22/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o s22/ev_$1_$2 --model $3 \
    --held-out glass,layers,interior,fog --grid 0 ) > s22/ev_$1_$2.log 2>&1; }
for s in heldout_g1sg8 heldout_g1fog heldout_g1int8 heldout_g1sg8_rot heldout_g1fog_rot heldout_g1int8_rot \
         heldout_g1sg8_yaw; do
    ev gzw2 $s $R/cpu-small-pdl-gzw-t2
    ev v5 $s cpu-small-pdl-gza-v5
done
ev gzw1 heldout_g1sg8_rot $R/cpu-small-pdl-gzw-t1
echo done > s22/chain2.done
# (the main chain resumed by hand)
