#!/usr/bin/env bash
# The main job on the built-in scene, from a fresh clone: install (cached venv), generate the scene,
# active training with lite_gs, render the test views, print the metrics table.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="$(bash scripts/setup_env.sh | tail -n 1)"
OUT="${OUT:-output/quickstart}"
"$PY" -m scene.builtin data/builtin
"$PY" train.py -s data/builtin -m "$OUT" --eval --method lite_gs --eps 0.1 \
    --num_init_views 2 --views_per_step 3 --max_views 11 --iters_per_view 40 --iterations 1500 \
    --num_random_points 4000 "$@"
"$PY" render.py -m "$OUT" --skip_train
"$PY" metrics.py -m "$OUT"
