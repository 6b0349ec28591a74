# sourced by session 32's chains: session 27's common.sh (data folder, environment, syn, ev) with logs and
# evaluations in s32
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
S=s32
mkdir -p $S
