#!/usr/bin/env bash
# The whole GPU check in one command (~8-9 min on an H200): CUDA tests, host-sync report, bench_gpu (ours vs gsplat),
# the paper-scale lite_gs and pop_gs slices. Writes 8 files to OUTDIR (default $OUT, else gpu_results/):
#   gpu_check.log  summary.md  pytest.txt  syncs.txt  bench_gpu.json  bench_gpu.md  slice_lite_gs.json  slice_pop_gs.json
#
#   bash benchmarks/gpu_prepare.sh                           # here, once: wheels + data link (see docs/gpu.md)
#   bash benchmarks/gpu_check.sh [OUTDIR]                    # on the GPU machine
#   GPU_CHECK_DEVICE=cpu bash benchmarks/gpu_check.sh /tmp/x # dry run of the plumbing on a CPU (tiny sizes)
#
# Env: GPU_CHECK_DEVICE (cuda|cpu), PY (python), DATA (folder holding lego/ and gsplat_garden/), SLICE_BUDGET_S
# (seconds per slice, default 150), TOTAL_S (deadline for the whole script, default 540).
set -u
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
OUTDIR="${1:-${OUT:-$ROOT/gpu_results}}"
DEVICE="${GPU_CHECK_DEVICE:-cuda}"
TOTAL_S="${TOTAL_S:-540}"
SLICE_BUDGET_S="${SLICE_BUDGET_S:-150}"
if [ -z "${PY:-}" ]; then
  if [ -x "$ROOT/.venv/bin/python" ]; then PY="$ROOT/.venv/bin/python"; else PY=python3; fi
fi
if [ -z "${DATA:-}" ]; then
  for d in "$ROOT/../shared/data" "$ROOT/benchmarks/gpu_data" "$ROOT/shared/data"; do
    if [ -d "$d/lego" ]; then DATA="$d"; break; fi
  done
fi
mkdir -p "$OUTDIR"
LOG="$OUTDIR/gpu_check.log"
export PYTHONUNBUFFERED=1
# The device machine's python does not have this checkout on its path (scripts/setup_env.sh's .venv does): add it.
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
START=$SECONDS
left() { echo $((TOTAL_S - (SECONDS - START))); }
say() { echo "[$((SECONDS - START)) s] $*" | tee -a "$LOG"; }
run_step() {  # run_step NAME LIMIT_S CMD... : output appended to the log; a timeout or failure is one line
  local name=$1 limit=$2
  shift 2
  [ "$limit" -gt "$(left)" ] && limit=$(left)
  if [ "$limit" -le 5 ]; then say "$name: SKIPPED (no time left)"; return 1; fi
  say "$name: start (limit $limit s)"
  timeout "$limit" "$@" >/tmp/gpu_check_step.txt 2>&1
  local rc=$?
  grep -v "USDT\|DeviceProperties" /tmp/gpu_check_step.txt >>"$LOG"
  [ -n "${STEP_OUT:-}" ] && grep -v "USDT\|DeviceProperties" /tmp/gpu_check_step.txt >"$STEP_OUT"
  if [ $rc -eq 124 ]; then say "$name: TIMED OUT after $limit s"; elif [ $rc -ne 0 ]; then say "$name: FAILED (exit $rc)"
  else say "$name: done"; fi
  return $rc
}

say "gpu_check: device=$DEVICE python=$PY data=${DATA:-none} out=$OUTDIR"
[ -n "${DATA:-}" ] || { say "error: no data folder with lego/ (set DATA or run benchmarks/gpu_prepare.sh)"; exit 2; }
if [ -d "$ROOT/benchmarks/wheels" ] && ls "$ROOT"/benchmarks/wheels/*.whl >/dev/null 2>&1; then
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/gpu_check_site \
    "$ROOT"/benchmarks/wheels/*.whl >>"$LOG" 2>&1 && export PYTHONPATH="/tmp/gpu_check_site${PYTHONPATH:+:$PYTHONPATH}" \
    && say "installed offline: $(cd "$ROOT/benchmarks/wheels" && ls ./*.whl | xargs -n1 basename | tr '\n' ' ')"
fi
{ nvidia-smi 2>/dev/null | head -15; "$PY" -c 'import torch, sys; print("python", sys.version.split()[0], "torch",
  torch.__version__, "cuda", torch.version.cuda, torch.cuda.get_device_name() if torch.cuda.is_available() else "no GPU")'
} >>"$LOG" 2>&1

if [ "$DEVICE" = cuda ]; then
  BENCH=(--device cuda); SLICE=(--device cuda --resolution 1 --num_points 100000 --budget_s "$SLICE_BUDGET_S")
  SYNCS=(--device cuda); PYTEST_MARK=cuda
  export TORCH_CUDA_ARCH_LIST="${TORCH_CUDA_ARCH_LIST:-9.0}" MAX_JOBS="${MAX_JOBS:-14}"  # build for Hopper only
  # gsplat's JIT build (~minutes, CPU cores) runs beside the GPU steps; bench_gpu then loads the cached build.
  ( PYTHONPATH="$ROOT/benchmarks${PYTHONPATH:+:$PYTHONPATH}" timeout 250 "$PY" -c \
      'import bench_gpu as b; print(b.gsplat_status(b.torch.device("cuda"), 240)[1])' >/tmp/gpu_check_gsplat.txt 2>&1 ) &
else
  BENCH=(--device cpu --tiny); SLICE=(--device cpu --resolution 8 --num_points 2000 --budget_s 20)
  SYNCS=(--device cpu --num_points 2000); PYTEST_MARK="cuda or not cuda"
fi

STEP_OUT="$OUTDIR/pytest.txt" run_step "pytest (cuda tests + their CPU self-check)" 150 "$PY" -m pytest \
  -p no:cacheprovider -q -rs -m "$PYTEST_MARK" tests/test_cuda.py tests/test_device_compare.py tests/test_device_flags.py
STEP_OUT="$OUTDIR/syncs.txt" run_step "host-sync report" 90 "$PY" benchmarks/gpu_syncs.py --data "$DATA/lego" \
  "${SYNCS[@]}"
if [ "$DEVICE" = cuda ]; then wait; say "gsplat first use: $(tail -n 3 /tmp/gpu_check_gsplat.txt 2>/dev/null)"; fi
run_step "bench_gpu" 200 "$PY" benchmarks/bench_gpu.py "${BENCH[@]}" --data "$DATA" --out "$OUTDIR"
for method in lite_gs pop_gs; do
  run_step "slice $method" $((SLICE_BUDGET_S + 120)) "$PY" benchmarks/gpu_slice.py --method "$method" \
    --data "$DATA/lego" "${SLICE[@]}" --out "$OUTDIR" --model "/tmp/gpu_check_slice_$method"
done

"$PY" - "$OUTDIR" <<'EOF' | tee "$OUTDIR/summary.md"
import json, sys
from pathlib import Path
out = Path(sys.argv[1])
print("# GPU check summary\n")
print("## pytest\n\n```\n" + (out / "pytest.txt").read_text() + "```\n")
bench = out / "bench_gpu.md"
print(bench.read_text() if bench.is_file() else "bench_gpu: no result (see gpu_check.log)\n")
print("## Paper-scale slices (Setup 1, streaming Fisher)\n")
keys = ("s_per_iteration", "stage0_iterations", "later_iterations", "gaussians_start", "acquisition_s",
        "oracle_evaluations", "fisher_s_per_oracle", "select_seconds", "peak_memory_mib", "projected_run_s")
for method in ("lite_gs", "pop_gs"):
    f = out / f"slice_{method}.json"
    if not f.is_file():
        print(f"- {method}: no result (timed out or failed; see gpu_check.log)")
        continue
    r = json.loads(f.read_text())
    if "note" in r:
        print(f"- {method}: {r['note']} (killed by its time limit); stage 0: {r['stage0_iterations']} iterations at "
              f"{r['stage0_s_per_iteration']:.3f} s/iteration, {r['gaussians_start']} Gaussians")
        continue
    print(f"- {method}: " + ", ".join(f"{k} {r[k]:.3f}" if isinstance(r[k], float) else f"{k} {r[k]}" for k in keys)
          + f" -> projected Setup 1 run {r['projected_run_s'] / 3600:.2f} h")
print("\n## Host syncs\n\n```\n" + (out / "syncs.txt").read_text()[:6000] + "```")
EOF
say "gpu_check finished in $((SECONDS - START)) s; results in $OUTDIR"
