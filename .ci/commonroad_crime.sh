#!/usr/bin/env bash
# Run commonroad-crime's criticality measures (TTC, THW, HW) on an exported CommonRoad scenario.
#
# usage: .ci/commonroad_crime.sh OUT_DIR RESULT_JSON [VENV_DIR]
#   OUT_DIR      folder written by `vid2sim export SCENARIO.json --format commonroad
#                --ego-as-obstacle --out OUT_DIR` (scenario.xml + ids.json)
#   RESULT_JSON  where to write the measures (one row per obstacle and time step)
#   VENV_DIR     the measures' virtual environment (default /tmp/vid2sim-crimevenv, or
#                $VID2SIM_CRIME_VENV); created on first use, reused when it has commonroad-crime.
#
# commonroad-crime 0.4.5 pins commonroad-io 2024.3 (which pins protobuf 3.20.2) and, through
# commonroad-reach, opencv-python 4; vid2sim needs protobuf >= 4.25.8 (onnxruntime, onnx) and
# opencv-python-headless 5. So, as the ASAM checkers, it lives in its own venv (about 1 GB)
# and reads the exported XML there (a cross-version read: the file is written by
# commonroad-io 2026.1).
set -euo pipefail

OUT_DIR=${1:?usage: .ci/commonroad_crime.sh OUT_DIR RESULT_JSON [VENV_DIR]}
RESULT=${2:?usage: .ci/commonroad_crime.sh OUT_DIR RESULT_JSON [VENV_DIR]}
VENV=${3:-${VID2SIM_CRIME_VENV:-/tmp/vid2sim-crimevenv}}
for f in "$OUT_DIR/scenario.xml" "$OUT_DIR/ids.json"; do
    [[ -f "$f" ]] || { echo "commonroad_crime: missing $f" >&2; exit 2; }
done

PY=${PYTHON:-python3}
if ! "$VENV/bin/python" -c "import commonroad_crime" >/dev/null 2>&1; then
    echo "commonroad_crime: creating the measures' venv in $VENV"
    "$PY" -m venv "$VENV"
    "$VENV/bin/pip" install -q --disable-pip-version-check "commonroad-crime==0.4.5"
fi
# its solver warns about every short polyline fit; the measures' log is kept for a failure
"$VENV/bin/python" "$(dirname "$0")/crime_measures.py" "$OUT_DIR/scenario.xml" \
    "$OUT_DIR/ids.json" "$RESULT" 2> "$RESULT.log" \
    || { tail -20 "$RESULT.log" >&2; echo "commonroad_crime: the measures failed" >&2; exit 1; }
