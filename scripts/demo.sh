#!/usr/bin/env bash
# Sets up pecs and runs the demo: the built-in checkerboard scene rendered spectrally and turned
# into the events of a DAVIS346. Outputs land in ./pecs-demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/pecs demo -o pecs-demo
