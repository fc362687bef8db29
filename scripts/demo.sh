#!/usr/bin/env bash
# Sets up pecs and runs the demo; outputs land in ./pecs-demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/pecs demo -o pecs-demo
