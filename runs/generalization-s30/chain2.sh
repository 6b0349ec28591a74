#!/bin/bash
# session 30: the kernels' temperature at inference (temp_diag.py), v8 with light matching, on a box-filtered and a
# Gaussian-filtered interior set and the box Sobol glass + layers set
. "$(dirname "$0")/common.sh"
for t in 0.7 0.85 1.2; do
  for s in heldout_g1int8_box heldout_g1int8 heldout_g1sg8_boxsob; do
    [ -f $S/ev_t${t}_$s/eval.md ] || ( time python $R/generalization-s30/temp_diag.py $t $s $S/ev_t${t}_$s ) \
        > $S/ev_t${t}_$s.log 2>&1
  done
done
touch $S/chain2.done
