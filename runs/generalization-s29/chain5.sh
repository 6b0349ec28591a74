# session 29, chain 5: the grid of section 1 with the noisy input's own light as the target instead of flat OIDN's
# (unbiased where OIDN's light is not, but noisy; section 5)
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
[ -f $S/lf_grid_noisy.jsonl ] || python $R/generalization-s29/lf_grid.py --noisy $S/lf_grid_noisy.jsonl $HELDOUT9 \
    > $S/lf_grid_noisy.log 2>&1
