#!/usr/bin/env bash
# Shared by the experiment wrappers (setup*.sh, ablation_ssg.sh): run scripts/grid.py for one setup.
# The protocols live in experiments/protocols.py; every option of grid.py works here too (see --help).
# Defaults: --launcher local, one job at a time. Environment: PYTHON (interpreter; default: the project's virtualenv
# .venv, created by scripts/setup_env.sh as quickstart.sh does when a fresh clone has none), EXTRA_TRAIN_ARGS
# (appended to every train.py call, e.g. "--sh_degree 1").
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -n "${PYTHON:-}" ]; then PY="$PYTHON"
elif [ -x "$ROOT/.venv/bin/python" ]; then PY="$ROOT/.venv/bin/python"
else PY="$(bash "$ROOT/scripts/setup_env.sh" | tail -n 1)"; fi

# run_grid SETUP [grid.py options...]
run_grid() {
  local setup=$1
  shift
  local extra=()
  # shellcheck disable=SC2206
  [ -n "${EXTRA_TRAIN_ARGS:-}" ] && extra=(-- ${EXTRA_TRAIN_ARGS})
  exec "$PY" "$ROOT/scripts/grid.py" --setup "$setup" --launcher local "$@" "${extra[@]}"
}
