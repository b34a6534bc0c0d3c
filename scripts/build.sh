#!/usr/bin/env bash
# Installs dependencies and builds idms in Release with CMake + Ninja (ccache when present).
# Everything lands in build/bin/. Usage: scripts/build.sh [extra cmake -D options]
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" > build.configure.log 2>&1 || {
  cat build.configure.log; exit 1; }
rm -f build.configure.log
jobs=$(nproc)
cmake --build build -j "$jobs"
