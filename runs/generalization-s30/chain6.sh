#!/bin/bash
# session 30: chain5's clamp at 1 standard error, the gain's move capped at 5% (se_clamp_eval.py 1 SET OUT 0.05)
. "$(dirname "$0")/common.sh"
for s in $HELDOUT9; do
  [ -f $S/ev_se1c5_$s/eval.md ] || ( time python $R/generalization-s30/se_clamp_eval.py 1 $s $S/ev_se1c5_$s 0.05 ) \
      > $S/ev_se1c5_$s.log 2>&1
done
touch $S/chain6.done
