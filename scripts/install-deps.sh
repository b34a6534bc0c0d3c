#!/usr/bin/env bash
# Installs every Debian package idms needs, and the npm packages from the committed lockfiles.
# Idempotent: quick when everything is present.
# Usage: scripts/install-deps.sh [--build-only]
#   --build-only: what building the programs needs (docker/'s build stage), without the fuzzers'
#                 clang, the benches' and tests' tools, or the test-only npm packages.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build_only=false
[ "${1:-}" = "--build-only" ] && build_only=true

packages=(
  build-essential cmake ninja-build ccache pkg-config git
  libeigen3-dev libboost-dev libboost-program-options-dev
  libprotobuf-dev protobuf-compiler libzstd-dev zlib1g-dev libssl-dev
  libosmesa6-dev libpng-dev libsqlite3-dev libpqxx-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev libspdlog-dev nlohmann-json3-dev
  libmeshoptimizer-dev libbullet-dev
  libnats-dev libcurl4-openssl-dev
  libceres-dev
  nodejs npm
)
# The tests' tools: chromium for the web viewer, prometheus for promtool (checks /metrics), docker,
# postgresql, nats-server, haproxy and OpenStack Swift (its s3api is the tests' S3 server) for the
# several-servers tests (they start their own, ctest -L scale).
$build_only || packages+=(
  postgresql
  clang libclang-rt-14-dev clang-format
  gnuplot-nox hyperfine rt-tests
  curl openssl wrk
  prometheus
  docker.io docker-compose debootstrap
  chromium
  nats-server haproxy
  swift-proxy swift-account swift-container swift-object
)
# The viewer's build needs viewer-web's packages; the tests need the others.
npm_dirs=(viewer-web)
$build_only || npm_dirs+=(tests/mcap-js tests/web)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# A machine with its own Node.js (node and npm on the PATH) keeps it.
if command -v node >/dev/null && command -v npm >/dev/null; then
  missing=("${missing[@]/#nodejs/}")
  missing=("${missing[@]/#npm/}")
  read -r -a missing <<< "${missing[*]}"
fi

if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}"
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install-deps: all ${#packages[@]} packages present"
fi

# npm ci only when node_modules is missing or older than its lockfile.
for dir in "${npm_dirs[@]}"; do
  if [ ! -d "$root/$dir/node_modules" ] || [ "$root/$dir/package-lock.json" -nt "$root/$dir/node_modules" ]; then
    echo "install-deps: npm ci in $dir"
    (cd "$root/$dir" && npm ci --no-audit --no-fund --loglevel=error) && touch "$root/$dir/node_modules"
  fi
done
