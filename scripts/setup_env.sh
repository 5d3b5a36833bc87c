#!/usr/bin/env bash
# Create (or reuse) the project's virtualenv, keyed by the hash of requirements.txt, and install this checkout into it
# in editable mode (pyproject.toml; `pip install -e . --no-deps`). Prints the venv's python path on the last line of
# stdout. Reused while the pins are unchanged, so CI and repeated set-ups take seconds. The virtualenv is shared by
# every checkout with the same pins, so the editable install is pointed at the current checkout on every call.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
key="$(sha256sum "$root/requirements.txt" | cut -c1-16)"
venv="${LITEGS_VENV_ROOT:-$HOME/.cache/litegs-venvs}/$key"
if [ ! -x "$venv/bin/python" ] || [ ! -f "$venv/.complete" ]; then
  echo "setup_env: creating virtualenv $venv (first time for these pins, ~2 min)" >&2
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$root/requirements.txt" >&2
  touch "$venv/.complete"
else
  echo "setup_env: reusing virtualenv $venv" >&2
fi
# The editable install: offline and in about a second when the venv already has setuptools>=64 (PEP 660).
isolation=()
if "$venv/bin/python" -c 'import sys, setuptools; sys.exit(int(setuptools.__version__.split(".")[0]) < 64)' 2>/dev/null
then isolation=(--no-build-isolation); fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps "${isolation[@]}" -e "$root" >&2
ln -sfn "$venv" "$root/.venv"  # .venv/bin/python is the project's python (a symlink, not tracked)
echo "$venv/bin/python"
