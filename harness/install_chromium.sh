#!/usr/bin/env bash
# Makes a headless Chromium available for the report test (tests/python/test_report.py renders
# report.html in a real browser). Idempotent: does nothing if a Chromium/Chrome is on PATH.
# Otherwise installs Debian/Ubuntu's `chromium` package with apt-get (as root, or with
# passwordless sudo). Prints the browser it found; exit 1 if none could be installed.
# Called by the test itself when no browser is found; harness/test.sh should call it before pytest.
set -uo pipefail
find_browser() {
  for b in chromium chromium-browser google-chrome google-chrome-stable; do
    if command -v "$b" >/dev/null 2>&1 && "$b" --version >/dev/null 2>&1; then
      command -v "$b"; return 0
    fi
  done
  return 1
}
if find_browser; then exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "install_chromium: no browser and no apt-get: install chromium by hand" >&2; exit 1
fi
if [ "$(id -u)" = 0 ]; then sudo=""
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo -n"
else echo "install_chromium: no browser, and not root nor passwordless sudo: cannot install chromium" >&2; exit 1
fi
echo "install_chromium: installing chromium with apt-get (about a minute)" >&2
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -q >/dev/null && $sudo apt-get install -y -q chromium >/dev/null 2>&1 \
  || $sudo apt-get install -y -q chromium-browser >/dev/null 2>&1 || true
find_browser || { echo "install_chromium: apt-get could not install chromium" >&2; exit 1; }
