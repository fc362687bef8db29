#!/usr/bin/env bash
# Sets up a development environment from a fresh clone: .venv with pecs installed (editable,
# release build of the Rust core) and the test tools. Safe to run again; rebuilds incrementally.
set -euo pipefail
cd "$(dirname "$0")/.."

command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust from https://rustup.rs" >&2; exit 1; }
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
