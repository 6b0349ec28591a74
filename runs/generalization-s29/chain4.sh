# session 29, chain 4: a gain per RGB channel (the grid of section 1) on top of the default light matching (stopped
# after four of the nine sets: the answer was clear; section 3)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
[ -f $S/lf_grid_rgb.jsonl ] || python $R/generalization-s29/lf_grid.py --rgb $S/lf_grid_rgb.jsonl $HELDOUT9 \
    > $S/lf_grid_rgb.log 2>&1
