# sourced by session 29's chains: session 28's common.sh (data folder, environment, ev, the nine held-out sets)
# with logs and evaluations in s29
. "$(dirname "${BASH_SOURCE[0]}")/../generalization-s28/common.sh"
S=s29
