# sourced by session 36's chains: session 35's common.sh (data folder, environment, syn, ev, trn, FAMILIES, SETS, V9)
# with logs and evaluations in s36
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s35/common.sh"
S=s36
mkdir -p $S
