#!/usr/bin/env bash
# Sets up pecs and runs the demo: a rotating quadrant disk filmed at 1000 fps, turned into the
# events of a DAVIS346. Outputs land in ./pecs-demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -c "from pecs.examples import write_quadrant_disk_frames as w; w('pecs-demo/frames')"
.venv/bin/pecs frames2events pecs-demo/frames --fps 1000 --preset davis346 -o pecs-demo/events.parquet
