# session 29, chain 4: the grid of section 1 with one gain per RGB channel instead of one from the luminance
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
[ -f $S/lf_grid_rgb.jsonl ] || python $R/generalization-s29/lf_grid.py --rgb $S/lf_grid_rgb.jsonl $HELDOUT9 \
    > $S/lf_grid_rgb.log 2>&1
