#!/usr/bin/env bash
# Installs dependencies and builds idms in Release with CMake + Ninja (ccache when present).
# Everything lands in build/bin/. Usage: scripts/build.sh [--build-only] [extra cmake -D options]
#   --build-only: the programs' packages only (scripts/install-deps.sh --build-only)
#   IDMS_BUILD_TARGETS="idms-server idms-agent": build only these targets (docker/'s build stage)
set -euo pipefail
cd "$(dirname "$0")/.."

deps_args=()
if [ "${1:-}" = "--build-only" ]; then
  deps_args=(--build-only)
  shift
fi
bash scripts/install-deps.sh "${deps_args[@]}"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" > build.configure.log 2>&1 || {
  cat build.configure.log; exit 1; }
rm -f build.configure.log
jobs=$(nproc)
targets=()
for t in ${IDMS_BUILD_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build build -j "$jobs" "${targets[@]}"
