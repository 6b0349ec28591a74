#!/bin/bash
# session 30: light matching with a clamp of K = 2 standard errors of the noisy box mean (se_clamp_eval.py), v8,
# on the nine held-out sets (without CAP: a fall held at 50%, a rise not bounded)
. "$(dirname "$0")/common.sh"
for s in $HELDOUT9; do
  [ -f $S/ev_se2_$s/eval.md ] || ( time python $R/generalization-s30/se_clamp_eval.py 2 $s $S/ev_se2_$s ) \
      > $S/ev_se2_$s.log 2>&1
done
touch $S/chain5.done
