#!/usr/bin/env bash
# Headless Chromium for the browser tests (tests/test_report_browser.py, tests/test_viewer_browser.py): Debian's
# chromium and chromium-driver packages, installed with apt-get when /usr/bin/chromium is missing. Nothing else is
# downloaded. Tolerant: without root or apt-get it says why and exits 0, and the browser tests skip with the reason.
set -uo pipefail
if [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; then
  echo "install_chromium: $(/usr/bin/chromium --version 2>/dev/null || echo chromium) already installed"
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "install_chromium: no apt-get (not Debian/Ubuntu); browser tests will skip" >&2
  exit 0
fi
SUDO=""
if [ "$(id -u)" != "0" ]; then
  if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then SUDO="sudo -n"; else
    echo "install_chromium: not root and no passwordless sudo; browser tests will skip" >&2
    exit 0
  fi
fi
export DEBIAN_FRONTEND=noninteractive
if ! $SUDO apt-get install -y -q chromium chromium-driver >/dev/null 2>&1; then
  $SUDO apt-get update -q >/dev/null 2>&1 || true
  $SUDO apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 \
    || { echo "install_chromium: apt-get install chromium chromium-driver failed; browser tests will skip" >&2; exit 0; }
fi
echo "install_chromium: installed $(/usr/bin/chromium --version 2>/dev/null)"
