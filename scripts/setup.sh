#!/usr/bin/env bash
# Sets up a development environment from a fresh clone: .venv with pecs installed (editable,
# release build of the Rust core) and the test tools. Safe to run again; rebuilds incrementally.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { echo "setup: $*" >&2; }
command -v cargo >/dev/null || { say "cargo not found; install Rust from https://rustup.rs"; exit 1; }
# Mitsuba's LLVM variants need libLLVM >= 16; install Debian's libllvm19 where we can.
if ! ls /usr/lib/*/libLLVM-1[6-9]*.so* /usr/lib/*/libLLVM.so.1[6-9]* >/dev/null 2>&1 && command -v apt-get >/dev/null; then
  if [ "$(id -u)" = 0 ]; then
    say "installing libllvm19 (Mitsuba's fast LLVM variants need it)"
    { apt-get install -y -q libllvm19 >/dev/null 2>&1 || { apt-get update -q >/dev/null && apt-get install -y -q libllvm19 >/dev/null; }; } || say "could not install libllvm19; rendering falls back to scalar_spectral"
  else say "no libLLVM >= 16; run 'sudo apt-get install libllvm19' for fast rendering"; fi
fi
[ -x .venv/bin/python ] || { say "creating .venv"; python3 -m venv .venv; }
.venv/bin/python -m pip install -q --upgrade pip
# The first run downloads Mitsuba, Ray and the test tools (a few hundred MB) and compiles the
# Rust core with full link-time optimisation: minutes on a 2-core machine, with no output from
# pip meanwhile. Later runs only rebuild what changed.
if [ -e target/release/lib_core.so ] || [ -e target/release/_core.dll ]; then
  say "installing pecs (rebuilding the Rust core if it changed)"
else
  say "installing pecs and its dependencies, building the Rust core in release mode (first run: several minutes)"
fi
start=$SECONDS
# cluster: Ray (about 80 MB), so that the tests run datasets on Ray too; docs: MkDocs, whose
# strict build is a stage of scripts/test.sh.
.venv/bin/python -m pip install -q -e '.[test,cluster,docs]'
say "pecs installed in .venv ($((SECONDS - start)) s)"
