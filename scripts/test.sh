#!/usr/bin/env bash
# Sets up and runs every check: formatting, lints, the Rust core's tests, the Python tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

echo "== cargo fmt / clippy"
cargo fmt --all --check
cargo clippy --release --workspace --all-targets -q -- -D warnings
echo "== ruff"
.venv/bin/ruff check python tests benches scenes
.venv/bin/ruff format --check python tests benches scenes
echo "== cargo test (core)"
cargo test --release -p pecs-core
echo "== pytest"
.venv/bin/python -m pytest -q "$@"
