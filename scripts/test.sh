#!/usr/bin/env bash
# Installs dependencies, builds everything (including the clang fuzz targets) and runs every
# test with CTest. Prints the number of tests. Usage: scripts/test.sh [ctest options]
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
cd build
echo "== ctest: $(ctest -N | sed -n 's/^Total Tests: //p') tests"
ctest --output-on-failure -j "$(nproc)" --timeout 900 "$@"
