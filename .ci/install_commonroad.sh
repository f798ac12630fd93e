#!/usr/bin/env bash
# Install commonroad-io 2026.1 (vid2sim export --format commonroad) into the active environment.
#
# usage: .ci/install_commonroad.sh      (after pip install -e ".[dev]", in the same venv)
#
# commonroad-io pins protobuf==3.20.2, and vid2sim's own dependencies need newer: onnxruntime
# >= 1.31 protobuf >= 4.25.8, onnx >= 1.22 protobuf >= 4.25.1 (1.23: >= 6.31.1), ray >= 2.60
# protobuf >= 3.20.3. pip's resolver therefore refuses `commonroad-io` in any extra of
# vid2sim. vid2sim uses only commonroad-io's XML reader and writer, which never import
# protobuf, so commonroad-io is installed without its dependencies and its other
# dependencies on their own (none of them conflicts). docs/commonroad.md says the same.
set -euo pipefail
pip install --quiet --disable-pip-version-check "commonroad-vehicle-models>=3.0.2" \
    "iso3166>=1.0.1" "omegaconf>=2.0" "rtree>=0.8.3" "lxml>=4.2.2"
pip install --quiet --disable-pip-version-check --no-deps "commonroad-io==2026.1"
python -c "import commonroad.common.writer.file_writer_xml, commonroad.common.reader.file_reader_xml"
echo "install_commonroad: commonroad-io 2026.1 installed (XML reader and writer import)"
