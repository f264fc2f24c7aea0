#!/usr/bin/env bash
# Makes Eigen's headers available for the C++ anchor of `progmo bench` (bench/cpp/anchor.cpp is
# built against Pinocchio's headers from the `pin` wheel plus Eigen, which the wheel does not ship).
# Idempotent: does nothing if Eigen/Core is found (/usr/include/eigen3, /usr/local/include/eigen3,
# or $EIGEN_INCLUDE_DIR). Otherwise installs Debian/Ubuntu's `libeigen3-dev` with apt-get (as
# root, or with passwordless sudo). Prints the include directory it found; exit 1 if none could be
# installed (the bench then skips the anchor and says why).
# Called by harness/setup.sh and by the bench's test when Eigen is missing.
set -uo pipefail
find_eigen() {
  for d in "${EIGEN_INCLUDE_DIR:-}" /usr/include/eigen3 /usr/local/include/eigen3; do
    if [ -n "$d" ] && [ -f "$d/Eigen/Core" ]; then echo "$d"; return 0; fi
  done
  return 1
}
if find_eigen; then exit 0; fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "install_eigen: no Eigen headers and no apt-get: install Eigen 3 by hand (or set EIGEN_INCLUDE_DIR)" >&2; exit 1
fi
if [ "$(id -u)" = 0 ]; then sudo=""
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo -n"
else echo "install_eigen: no Eigen headers, and not root nor passwordless sudo: cannot install libeigen3-dev" >&2; exit 1
fi
echo "install_eigen: installing libeigen3-dev with apt-get" >&2
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get install -y -q libeigen3-dev >/dev/null 2>&1 \
  || { $sudo apt-get update -q >/dev/null 2>&1 && $sudo apt-get install -y -q libeigen3-dev >/dev/null 2>&1; } || true
find_eigen || { echo "install_eigen: apt-get could not install libeigen3-dev" >&2; exit 1; }
