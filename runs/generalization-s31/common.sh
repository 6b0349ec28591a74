# sourced by session 31's chains: session 27's common.sh (data folder, environment, syn, ev) with logs and
# evaluations in s31, and evc: ev through clean_aux.py (OIDN's prefiltered aux in the prior, the baseline or both)
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
S=s31
mkdir -p $S
# evc WHERE TAG SET MODEL: as ev, with clean_aux.py --where WHERE
evc() { [ -f $S/ev_$2_$3/eval.md ] || ( time python $R/generalization-s31/clean_aux.py --where $1 $3 \
    -o $S/ev_$2_$3 --model $4 --held-out glass,layers,interior,fog --grid 0 ) > $S/ev_$2_$3.log 2>&1; }
