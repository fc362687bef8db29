#!/usr/bin/env bash
# Sets up and runs every check: formatting, lints, the Rust core's tests, the Python tests.
# The Rust core's dependencies are compiled by the extension's release build in setup.sh, and
# the core's test build reuses them (rust/core/Cargo.toml names the features the bindings turn
# on; the criterion benches live in rust/bench): it compiles pecs-core and the six crates
# under exr and obvhs whose proc-macro's syn the bindings build with more features, about 20 s
# of the stage on 2 cores. Where the time went is printed at the end.
set -euo pipefail
cd "$(dirname "$0")/.."

timings=""
run_stage() {  # run_stage NAME COMMAND...: run it, note how long it took
  local name=$1 start=$SECONDS
  shift
  echo "== $name" >&2
  "$@"
  timings+=$(printf '  %-34s %5d s' "$name" $((SECONDS - start)))$'\n'
}
report() {
  local rc=$?
  printf '\ntest.sh: where the time went (%d s in all, exit %d)\n%s' "$SECONDS" "$rc" "$timings" >&2
}
trap report EXIT

run_stage "setup (venv, release build)" bash scripts/setup.sh
run_stage "cargo fmt" cargo fmt --all --check
run_stage "cargo clippy" cargo clippy --release --workspace --all-targets -q -- -D warnings
run_stage "ruff" bash -c '.venv/bin/ruff check python tests benches scenes scripts && .venv/bin/ruff format --check python tests benches scenes scripts'
run_stage "cargo test (core)" cargo test --release -p pecs-core
# Broken links, missing pages and API references fail the strict build; the site goes to a
# temporary folder, never into the repository.
run_stage "docs (mkdocs --strict)" env NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict -q -d "$(mktemp -d)"
run_stage "pytest" .venv/bin/python -m pytest -q "$@"
