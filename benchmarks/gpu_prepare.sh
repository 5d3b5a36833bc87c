#!/usr/bin/env bash
# Before a device run (on the machine with the checkout, PyPI reachable): the wheels the GPU machine lacks
# (gsplat 1.5.3, pure Python, JIT-compiles there; plyfile) into benchmarks/wheels/, and benchmarks/gpu_data, a link to
# ../shared/data, so that `carry` can name benchmarks/gpu_data/lego and benchmarks/gpu_data/gsplat_garden (the
# ../shared beside a checkout does not travel). Both paths are gitignored. gsplat's own needs (torch, numpy, ninja,
# jaxtyping, rich) are already on the GPU machine.
set -eu
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
PY="${PY:-$ROOT/.venv/bin/python}"
mkdir -p "$ROOT/benchmarks/wheels"
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 -d "$ROOT/benchmarks/wheels" \
  gsplat==1.5.3 plyfile==1.1.5
[ -e "$ROOT/benchmarks/gpu_data" ] || ln -s "$(cd "$ROOT/../shared/data" && pwd)" "$ROOT/benchmarks/gpu_data"
ls -la "$ROOT/benchmarks/wheels" "$ROOT/benchmarks/gpu_data/"
du -shL "$ROOT/benchmarks/wheels" "$ROOT/benchmarks/gpu_data/lego" "$ROOT/benchmarks/gpu_data/gsplat_garden"
