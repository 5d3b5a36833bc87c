#!/usr/bin/env bash
# Shared option parsing and the run loop of the experiment scripts (sourced by setup*.sh / ablation_ssg.sh).
# A sourcing script sets its protocol defaults (DEFAULT_SCENES, DEFAULT_METHODS) before sourcing, then calls
# parse_args "$@", one or more run_setup / run_one, and finish SETUP.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -n "${PYTHON:-}" ]; then PY="$PYTHON"
elif [ -x "$ROOT/.venv/bin/python" ]; then PY="$ROOT/.venv/bin/python"
else PY="python"; fi
EXTRA_TRAIN_ARGS="${EXTRA_TRAIN_ARGS:-}"  # appended to every train.py call (e.g. "--sh_degree 1")

DATA="$ROOT/../shared/data"
OUT="$ROOT/output/experiments"
SCENES="${DEFAULT_SCENES:-lego}"
METHODS="${DEFAULT_METHODS:-random pop_gs lite_gs}"
SEEDS=1
RESOLUTION=8
ITER_SCALE=0.1  # CPU-sized: Setup 1 on lego at 100 px, 3 methods, 1 seed, 2 cores: see the README's Results
NUM_POINTS=3000
EPS=0.1
DEVICE=auto
FAILED=0

usage() {
  cat <<USAGE
usage: $(basename "$0") [--data DIR] [--out DIR] [--scenes "a b"] [--methods "m1 m2"] [--seeds N]
                        [--resolution R] [--iter_scale F] [--num_points P] [--eps E] [--device auto|cpu|cuda]
  --data        dataset root holding one directory per scene (default: ../shared/data)
  --out         output root; runs go to OUT/<setup>/<scene>/<method>[_k<K>][_eps<E>]/seed<S> (default: output/experiments)
  --scenes      scene directory names under --data (default: $SCENES)
  --methods     selectors to compare (default: $METHODS)
  --seeds       number of seeds, run as 0..N-1 (default: $SEEDS)
  --resolution  train.py -r value (default: $RESOLUTION, i.e. 100 px for 800 px Blender scenes)
  --iter_scale  multiplies iterations per view, total iterations, the densification start (500) and the opacity
                reset interval (3000), rounded, at least 1; the densification interval stays 100, so a reduced run
                densifies fewer times (1 = paper; default: $ITER_SCALE)
  --num_points  random initial points for synthetic scenes (paper: 100000; default: $NUM_POINTS)
  --eps         lite_gs/ssg accuracy parameter where the protocol does not fix it (default: $EPS)
  --device      torch device for training (default: auto = cuda when available)
Reruns skip runs that have results.json and resume the others. Use a new --out when changing budgets.
Environment: PYTHON (interpreter), EXTRA_TRAIN_ARGS (appended to every train.py call).
USAGE
}

die() {  # one line on stderr, exit 2 (a user error)
  echo "error: $*" >&2
  exit 2
}

is_number() { [[ $1 =~ ^[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?$ ]]; }

parse_args() {
  while [ $# -gt 0 ]; do
    case "$1" in
      -h|--help) usage; exit 0 ;;
      --data|--out|--scenes|--methods|--seeds|--resolution|--iter_scale|--num_points|--eps|--device)
        [ $# -ge 2 ] || die "option $1 needs a value (see --help)"
        case "$1" in
          --data) DATA="$2" ;; --out) OUT="$2" ;; --scenes) SCENES="$2" ;; --methods) METHODS="$2" ;;
          --seeds) SEEDS="$2" ;; --resolution) RESOLUTION="$2" ;; --iter_scale) ITER_SCALE="$2" ;;
          --num_points) NUM_POINTS="$2" ;; --eps) EPS="$2" ;; --device) DEVICE="$2" ;;
        esac
        shift 2 ;;
      *) die "unknown option $1 (see --help)" ;;
    esac
  done
  [[ $SEEDS =~ ^[1-9][0-9]*$ ]] || die "--seeds must be a positive integer, got '$SEEDS'"
  [[ $NUM_POINTS =~ ^[1-9][0-9]*$ ]] || die "--num_points must be a positive integer, got '$NUM_POINTS'"
  is_number "$ITER_SCALE" && awk -v s="$ITER_SCALE" 'BEGIN { exit !(s > 0) }' \
    || die "--iter_scale must be a positive number, got '$ITER_SCALE'"
  is_number "$EPS" && awk -v e="$EPS" 'BEGIN { exit !(e > 0 && e < 1) }' \
    || die "--eps must be a number in (0, 1), got '$EPS'"
  [ -n "${SCENES// /}" ] || die "--scenes is empty; name at least one scene directory under --data"
  [ -n "${METHODS// /}" ] || die "--methods is empty; name at least one of random pop_gs lite_gs ssg"
  for scene in $SCENES; do
    if [ ! -d "$DATA/$scene" ]; then
      found="$(find "$DATA" -mindepth 1 -maxdepth 1 -type d -printf '%f ' 2>/dev/null | sed 's/ $//' || true)"
      die "scene directory $DATA/$scene not found; scenes in $DATA: ${found:-none} (use --data / --scenes)"
    fi
  done
  case "$DEVICE" in
    auto) DEVICE="$("$PY" -c 'import torch; print("cuda" if torch.cuda.is_available() else "cpu")')" ;;
    cpu|cuda) ;;
    *) die "--device must be auto, cpu or cuda, got '$DEVICE'" ;;
  esac
}

scaled() {  # scaled N -> max(1, round(N * ITER_SCALE)), halves rounded up
  awk -v n="$1" -v s="$ITER_SCALE" 'BEGIN { r = int(n * s + 0.5); print (r < 1 ? 1 : r) }'
}

# tag_for METHOD K EPS WITH_K WITH_EPS -> directory name METHOD[_k<K>][_eps<E>]. The eps suffix is added when
# WITH_EPS is "always", or for lite_gs/ssg when eps is not the paper's default 0.1 (so runs never collide).
tag_for() {
  local tag=$1
  [ "$4" = yes ] && tag+="_k$2"
  if [ "$5" = always ] || { [[ $1 == lite_gs || $1 == ssg ]] && awk -v e="$3" 'BEGIN { exit !(e != 0.1) }'; }; then
    tag+="_eps$3"
  fi
  echo "$tag"
}

# run_one SETUP SCENE METHOD TAG SEED NUM_INIT K MAX_VIEWS ITERS_PER_VIEW TOTAL EPS:
# train (resuming a partial run), render the test views, compute metrics; skipped when results.json exists.
run_one() {
  local setup=$1 scene=$2 method=$3 tag=$4 seed=$5 n0=$6 k=$7 vmax=$8 ipv=$9 total=${10} eps=${11}
  local model="$OUT/$setup/$scene/$tag/seed$seed" label="[$setup] $scene $tag seed $seed"
  if [ -f "$model/results.json" ]; then
    echo "$label: done, skipping"
    return 0
  fi
  local bg=()
  [ -f "$DATA/$scene/transforms_train.json" ] && bg=(--white_background)  # Blender scenes: RGBA on white
  echo "$label: training"
  local t0=$SECONDS
  # shellcheck disable=SC2086
  if "$PY" "$ROOT/train.py" -s "$DATA/$scene" -m "$model" --eval -r "$RESOLUTION" "${bg[@]}" --device "$DEVICE" \
        --seed "$seed" --method "$method" --eps "$eps" --num_init_views "$n0" --views_per_step "$k" \
        --max_views "$vmax" --iters_per_view "$(scaled "$ipv")" --iterations "$(scaled "$total")" \
        --num_random_points "$NUM_POINTS" --densify_from_iter "$(scaled 500)" \
        --opacity_reset_interval "$(scaled 3000)" --quiet $EXTRA_TRAIN_ARGS \
     && "$PY" "$ROOT/render.py" -m "$model" --skip_train --quiet \
     && "$PY" "$ROOT/metrics.py" -m "$model" --quiet > /dev/null; then
    echo "$label: finished in $((SECONDS - t0)) s"
  else
    echo "$label: FAILED after $((SECONDS - t0)) s (error above); continuing, rerun to resume it" >&2
    FAILED=$((FAILED + 1))
  fi
}

# run_setup SETUP NUM_INIT K MAX_VIEWS ITERS_PER_VIEW TOTAL [WITH_K]: every scene x method x seed at one K.
run_setup() {
  local setup=$1 n0=$2 k=$3 vmax=$4 ipv=$5 total=$6 with_k=${7:-no}
  for scene in $SCENES; do
    for method in $METHODS; do
      for seed in $(seq 0 $((SEEDS - 1))); do
        run_one "$setup" "$scene" "$method" "$(tag_for "$method" "$k" "$EPS" "$with_k" auto)" "$seed" \
          "$n0" "$k" "$vmax" "$ipv" "$total" "$EPS"
      done
    done
  done
}

has_method() { [[ " $METHODS " == *" $1 "* ]]; }

# finish SETUP: tables and plots for OUT/SETUP; exit 1 when a run failed.
finish() {
  if [ -n "$(find "$OUT/$1" -name selection.json -print -quit 2>/dev/null)" ]; then
    "$PY" "$ROOT/scripts/summarize.py" "$OUT/$1" --out "$OUT/$1" || FAILED=$((FAILED + 1))
  fi
  if [ "$FAILED" -gt 0 ]; then
    echo "error: $FAILED run(s) failed; rerun the same command to resume them" >&2
    exit 1
  fi
}
