#!/usr/bin/env bash
# Shared option parsing and the run loop of the experiment scripts (sourced by setup*.sh / ablation_ssg.sh).
# Every script takes the same options; the protocol constants come from the script that sources this file.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-$ROOT/.venv/bin/python}"
[ -x "$PY" ] || PY="$(command -v python3)"

DATA="${DATA:-$ROOT/../shared/data}"
OUT="${OUT:-$ROOT/output/experiments}"
SCENES="${SCENES:-lego}"
METHODS="${METHODS:-random pop_gs lite_gs}"
SEEDS="${SEEDS:-1}"
RESOLUTION="${RESOLUTION:-8}"
ITER_SCALE="${ITER_SCALE:-0.2}"
NUM_POINTS="${NUM_POINTS:-5000}"
EPS="${EPS:-0.1}"
EXTRA_TRAIN_ARGS="${EXTRA_TRAIN_ARGS:-}"

usage() {
  cat <<USAGE
usage: $(basename "$0") [--data DIR] [--out DIR] [--scenes "a b"] [--methods "random pop_gs lite_gs"]
                        [--seeds N] [--resolution R] [--iter_scale F] [--num_points P] [--eps E]
  --data        dataset root holding one directory per scene (default: ../shared/data)
  --out         output root (default: output/experiments)
  --iter_scale  multiplies iterations per view and total iterations (1 = paper scale; default 0.2 for CPU)
  --resolution  train.py -r value (default 8: 100 px for Blender scenes)
  --num_points  random initial points for synthetic scenes (paper: 100000)
Reruns skip runs that finished (results.json) and resume those that did not.
USAGE
}

parse_args() {
  while [ $# -gt 0 ]; do
    case "$1" in
      --data) DATA="$2"; shift 2 ;;
      --out) OUT="$2"; shift 2 ;;
      --scenes) SCENES="$2"; shift 2 ;;
      --methods) METHODS="$2"; shift 2 ;;
      --seeds) SEEDS="$2"; shift 2 ;;
      --resolution) RESOLUTION="$2"; shift 2 ;;
      --iter_scale) ITER_SCALE="$2"; shift 2 ;;
      --num_points) NUM_POINTS="$2"; shift 2 ;;
      --eps) EPS="$2"; shift 2 ;;
      -h|--help) usage; exit 0 ;;
      *) echo "error: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
  done
  for scene in $SCENES; do
    if [ ! -d "$DATA/$scene" ]; then
      found="$(find "$DATA" -mindepth 1 -maxdepth 1 -type d -printf '%f ' 2>/dev/null || true)"
      echo "error: scene directory $DATA/$scene not found; scenes in $DATA: ${found:-none} (use --data / --scenes)" >&2
      exit 2
    fi
  done
}

scaled() {  # scaled N -> max(1, round(N * ITER_SCALE))
  "$PY" -c "import sys; print(max(1, round(float(sys.argv[1]) * float(sys.argv[2]))))" "$1" "$ITER_SCALE"
}

# run_one SETUP SCENE METHOD TAG SEED NUM_INIT K MAX_VIEWS ITERS_PER_VIEW TOTAL EPS
run_one() {
  local setup=$1 scene=$2 method=$3 tag=$4 seed=$5 n0=$6 k=$7 vmax=$8 ipv=$9 total=${10} eps=${11}
  local model="$OUT/$setup/$scene/$tag/seed$seed"
  if [ -f "$model/results.json" ]; then
    echo "[$setup] $scene $tag seed $seed: done, skipping"
    return
  fi
  echo "[$setup] $scene $tag seed $seed: training"
  local t0=$SECONDS
  # shellcheck disable=SC2086
  "$PY" "$ROOT/train.py" -s "$DATA/$scene" -m "$model" --eval -r "$RESOLUTION" --white_background \
      --seed "$seed" --method "$method" --eps "$eps" --num_init_views "$n0" --views_per_step "$k" \
      --max_views "$vmax" --iters_per_view "$(scaled "$ipv")" --iterations "$(scaled "$total")" \
      --num_random_points "$NUM_POINTS" --quiet $EXTRA_TRAIN_ARGS
  "$PY" "$ROOT/render.py" -m "$model" --skip_train --quiet
  "$PY" "$ROOT/metrics.py" -m "$model" --quiet > /dev/null
  echo "[$setup] $scene $tag seed $seed: finished in $((SECONDS - t0)) s"
}

# run_setup SETUP NUM_INIT K MAX_VIEWS ITERS_PER_VIEW TOTAL: every scene x method x seed at one K and EPS.
run_setup() {
  local setup=$1 n0=$2 k=$3 vmax=$4 ipv=$5 total=$6 suffix=${7:-}
  for scene in $SCENES; do
    for method in $METHODS; do
      for seed in $(seq 0 $((SEEDS - 1))); do
        run_one "$setup" "$scene" "$method" "$method$suffix" "$seed" "$n0" "$k" "$vmax" "$ipv" "$total" "$EPS"
      done
    done
  done
}

summarize() {
  "$PY" "$ROOT/scripts/summarize.py" "$OUT/$1" --out "$OUT/$1"
}
