#!/bin/bash
# Held-out and in-family tables of a model against the baselines (and cpu-small-v1), as in the model card.
# Usage: runs/cpu-small-p-t1/evaluate.sh MODEL DATA_DIR OUT_DIR   (DATA_DIR holds heldout_g1 and infam_g1)
set -euo pipefail
MODEL=${1:-runs/cpu-small-p-t1}; DATA=${2:-data}; OUT=${3:-runs/cpu-small-p-t1}
ranad eval "$DATA/heldout_g1" -o "$OUT/eval-heldout" --model "$MODEL" --held-out glass,layers --grid 6
ranad eval "$DATA/infam_g1" -o "$OUT/eval-infamily" --model "$MODEL" --held-out glass,layers --grid 6
ranad eval "$DATA/heldout_g1" -o "$OUT/eval-exposure" --model "$MODEL" --held-out glass,layers --spp 16 \
    --kind deepz --exposure -6,-3,0,3,6 --grid 0
