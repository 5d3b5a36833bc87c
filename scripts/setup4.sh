#!/usr/bin/env bash
# Setup 4 (paper): 3 seed views, K in {3, 4, 6} to 15 views, 300 v iterations per stage, 15,000 in total
# (Blender ship); every method at each K with --eps (paper: 0.1), and for K = 6 also lite_gs at eps 0.3 and 0.6.
DEFAULT_SCENES=ship
source "$(dirname "$0")/common.sh"
parse_args "$@"
for k in 3 4 6; do
  run_setup setup4 3 "$k" 15 300 15000 yes
done
if has_method lite_gs; then
  for eps in 0.3 0.6; do
    awk -v a="$eps" -v b="$EPS" 'BEGIN { exit !(a == b) }' && continue  # already run above
    for scene in $SCENES; do
      for seed in $(seq 0 $((SEEDS - 1))); do
        run_one setup4 "$scene" lite_gs "$(tag_for lite_gs 6 "$eps" yes always)" "$seed" 3 6 15 300 15000 "$eps"
      done
    done
  done
fi
finish setup4
