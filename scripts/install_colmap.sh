#!/usr/bin/env bash
# Install COLMAP (used by convert.py) from the Debian/Ubuntu package: `apt-get install colmap`.
# A no-op when `colmap` is already on PATH. Needs root and apt-get; otherwise it says so and exits 1
# (install COLMAP by other means: https://colmap.github.io/install.html, then put it on PATH).
# The Debian build has no CUDA; convert.py runs SIFT on the CPU.
set -euo pipefail
if command -v colmap >/dev/null 2>&1; then
  echo "install_colmap: colmap already on PATH ($(command -v colmap))"
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "install_colmap: error: apt-get not available; install COLMAP by other means (https://colmap.github.io/install.html)" >&2
  exit 1
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "install_colmap: error: needs root to run apt-get (run: sudo bash scripts/install_colmap.sh)" >&2
  exit 1
fi
echo "install_colmap: apt-get update && apt-get install -y colmap (a few minutes the first time)"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends colmap >/dev/null
echo "install_colmap: installed $(command -v colmap)"
