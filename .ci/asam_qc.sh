#!/usr/bin/env bash
# Run the ASAM Quality Checker bundles on an exported scenario (scenario.xosc + road.xodr).
#
# usage: .ci/asam_qc.sh OUT_DIR [VENV_DIR]
#   OUT_DIR   folder written by `vid2sim export SCENARIO.json --format openscenario --out OUT_DIR`
#   VENV_DIR  where to create the checkers' virtual environment (default /tmp/vid2sim-qcvenv,
#             or $VID2SIM_QC_VENV); reused when it already has both checkers.
#
# The checker bundles (asam-qc-openscenarioxml, asam-qc-opendrive) pin old numpy and lxml, so
# they live in their own venv, never in the project's. Each bundle takes an XML configuration
# naming the input file and writes an .xqar result file; qc_baselib reads the results back.
# Exit 0 only if both bundles report 0 issues and every checker COMPLETED, except checkers the
# bundle SKIPPED because their rule applies to other standard versions (their summary says so);
# any other skip or an error fails.
set -euo pipefail

OUT_DIR=${1:?usage: .ci/asam_qc.sh OUT_DIR [VENV_DIR]}
VENV=${2:-${VID2SIM_QC_VENV:-/tmp/vid2sim-qcvenv}}
OUT_DIR=$(cd "$OUT_DIR" && pwd)
XOSC="$OUT_DIR/scenario.xosc"
XODR="$OUT_DIR/road.xodr"
for f in "$XOSC" "$XODR"; do
    [[ -f "$f" ]] || { echo "asam_qc: missing $f" >&2; exit 2; }
done

PY=${PYTHON:-python3}
if [[ ! -x "$VENV/bin/qc_opendrive" || ! -x "$VENV/bin/qc_openscenario" ]]; then
    echo "asam_qc: creating checker venv in $VENV"
    "$PY" -m venv "$VENV"
    "$VENV/bin/pip" install -q --disable-pip-version-check \
        "asam-qc-baselib>=1.0" "asam-qc-opendrive>=1.0" "asam-qc-openscenarioxml>=1.0"
fi

WORK=$(mktemp -d "${TMPDIR:-/tmp}/vid2sim-qc.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

write_config() {  # input_file bundle_name result_file config_file
    cat > "$4" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<Config>
    <Param name="InputFile" value="$1"/>
    <CheckerBundle application="$2">
        <Param name="resultFile" value="$3"/>
    </CheckerBundle>
</Config>
XML
}

write_config "$XODR" xodrBundle "$WORK/xodr.xqar" "$WORK/xodr_config.xml"
write_config "$XOSC" xoscBundle "$WORK/xosc.xqar" "$WORK/xosc_config.xml"
# the checkers log every step at INFO; keep their output for a failure report only
(cd "$WORK" && "$VENV/bin/qc_opendrive" -c "$WORK/xodr_config.xml") > "$WORK/xodr.log" 2>&1 \
    || { cat "$WORK/xodr.log"; echo "asam_qc: qc_opendrive crashed" >&2; exit 1; }
(cd "$WORK" && "$VENV/bin/qc_openscenario" -c "$WORK/xosc_config.xml") > "$WORK/xosc.log" 2>&1 \
    || { cat "$WORK/xosc.log"; echo "asam_qc: qc_openscenario crashed" >&2; exit 1; }

"$VENV/bin/python" - "$WORK/xodr.xqar" "$WORK/xosc.xqar" <<'PY'
import sys

from qc_baselib import Result, StatusType

failed = False
for path in sys.argv[1:]:
    result = Result()
    result.load_from_file(path)
    for bundle in result.get_checker_bundle_results():
        counts = {"completed": 0, "skipped_version": 0}
        problems = []
        for checker in bundle.checkers:
            summary = checker.summary or ""
            if checker.status == StatusType.COMPLETED:
                counts["completed"] += 1
            elif checker.status == StatusType.SKIPPED and "not valid according to" in summary:
                counts["skipped_version"] += 1  # rule limited to other standard versions
            else:
                problems.append(f"  {checker.checker_id}: {checker.status} {summary}")
            for issue in checker.issues:
                problems.append(f"  {checker.checker_id}: {issue.level.name} "
                                f"{issue.rule_uid}: {issue.description}")
        n_issues = result.get_checker_bundle_issue_count(bundle.name)
        ok = not problems and n_issues == 0
        failed |= not ok
        print(f"{bundle.name}: {len(bundle.checkers)} checkers, {counts['completed']} completed, "
              f"{counts['skipped_version']} skipped for version, {n_issues} issues "
              f"-> {'PASS' if ok else 'FAIL'}")
        for line in problems:
            print(line)
sys.exit(1 if failed else 0)
PY
