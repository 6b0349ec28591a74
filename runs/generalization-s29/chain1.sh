# session 29, chain 1: the shipped default (cpu-small-pdl-gza-v8) scored with light matching (lightmatch.py, on by
# default in ranad denoise and ranad eval) on the nine held-out sets, the two scene-generator sets and the in-family
# box set; session 28's v8 folders (s28/ev_flt1h_*: the same model, no light matching) are the comparison
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
mkdir -p $S
ev_sets lm8 cpu-small-pdl-gza-v8 $HELDOUT9 heldout_g3s2 heldout_g3s2g infam_g36_box
