# sourced by session 33's chains: session 27's common.sh (data folder, environment, syn, ev) with logs and
# evaluations in s33
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s27/common.sh"
S=s33
mkdir -p $S
