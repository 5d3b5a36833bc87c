#!/usr/bin/env bash
# Create (or reuse) the project's python: a package virtualenv keyed by the hash of requirements.txt, shared by every
# checkout with the same pins, and this checkout's own .venv on top of it (a small virtualenv whose .pth file puts
# this checkout's root first on the path, then the shared packages). Nothing of the project is installed into the
# shared virtualenv (an editable install left there by an older set-up is removed), so each checkout runs its own
# code. Prints .venv's python path on the last line of stdout. The shared virtualenv is built (about 2 minutes) under
# an exclusive lock next to it, so concurrent first set-ups wait for one build; later calls take about a second.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
key="$(sha256sum "$root/requirements.txt" | cut -c1-16)"
venvs="${LITEGS_VENV_ROOT:-$HOME/.cache/litegs-venvs}"
venv="$venvs/$key"
mkdir -p "$venvs"
exec 9>"$venv.lock"  # held until this script exits (the shared build and this checkout's .venv)
flock -n 9 || { echo "setup_env: waiting for another set-up of $venv" >&2; flock 9; }
if [ ! -x "$venv/bin/python" ] || [ ! -f "$venv/.complete" ]; then
  echo "setup_env: creating virtualenv $venv (first time for these pins, ~2 min)" >&2
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$root/requirements.txt" >&2
  touch "$venv/.complete"
else
  echo "setup_env: reusing virtualenv $venv" >&2
fi
if compgen -G "$venv/lib/python*/site-packages/litegs_active-*.dist-info" >/dev/null; then
  echo "setup_env: removing the editable install of litegs-active from $venv (checkouts no longer share one)" >&2
  "$venv/bin/python" -m pip uninstall -q -y --disable-pip-version-check litegs-active >&2
fi
overlay="$root/.venv"  # untracked; older set-ups made it a symlink to the shared virtualenv
[ -L "$overlay" ] && rm "$overlay"
if [ ! -x "$overlay/bin/python" ] || [ "$(grep -E '^(home|version) =' "$venv/pyvenv.cfg")" != \
     "$(grep -E '^(home|version) =' "$overlay/pyvenv.cfg" 2>/dev/null)" ]; then
  rm -rf "$overlay"
  "$venv/bin/python" -m venv --without-pip "$overlay"  # the shared virtualenv's base interpreter
fi
shared_site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("purelib"))')"
# The checkout's root, then the shared packages (site.addsitedir also reads their own .pth files).
"$overlay/bin/python" - "$root" "$shared_site" <<'EOF'
import os, sys, sysconfig
root, shared_site = sys.argv[1:]
pth = os.path.join(sysconfig.get_path("purelib"), "litegs_checkout.pth")
with open(pth + ".tmp", "w") as f:
    f.write(f"{root}\nimport site; site.addsitedir({shared_site!r})\n")
os.replace(pth + ".tmp", pth)
EOF
echo "$overlay/bin/python"
