# sourced by session 30's chains: session 28's common.sh (data folder, environment, ev, the nine held-out sets, the
# t16 fine-tuning options) with logs and evaluations in s30
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s28/common.sh"
S=s30
mkdir -p $S
# evn TAG SET MODEL: as ev, without light matching (comparable with session 28's evaluations, made before it existed)
evn() { [ -f $S/ev_$1_$2/eval.md ] || ( time ranad eval $2 -o $S/ev_$1_$2 --model $3 --no-light-match \
    --held-out glass,layers,interior,fog --grid 0 ) > $S/ev_$1_$2.log 2>&1; }
