#!/usr/bin/env bash
# Sets up a development environment from a fresh clone: .venv with pecs installed (editable,
# release build of the Rust core) and the test tools. Safe to run again; rebuilds incrementally.
set -euo pipefail
cd "$(dirname "$0")/.."

command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust from https://rustup.rs" >&2; exit 1; }
# Mitsuba's LLVM variants need libLLVM >= 16; install Debian's libllvm19 where we can.
if ! ls /usr/lib/*/libLLVM-1[6-9]*.so* /usr/lib/*/libLLVM.so.1[6-9]* >/dev/null 2>&1 && command -v apt-get >/dev/null; then
  if [ "$(id -u)" = 0 ]; then { apt-get install -y -q libllvm19 >/dev/null 2>&1 || { apt-get update -q >/dev/null && apt-get install -y -q libllvm19 >/dev/null; }; } || echo "setup: could not install libllvm19; rendering falls back to scalar_spectral" >&2
  else echo "setup: no libLLVM >= 16; run 'sudo apt-get install libllvm19' for fast rendering" >&2; fi
fi
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
# cluster: Ray (about 80 MB), so that the tests run datasets on Ray too.
.venv/bin/python -m pip install -q -e '.[test,cluster]'
