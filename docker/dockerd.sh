#!/usr/bin/env bash
# Starts a private dockerd for idms (its own data root and socket, --bridge=none: containers use
# the host's network, so every connection stays on loopback) unless one already answers, and
# prints the DOCKER_HOST to use. Exit 3 (with the reason on stderr) where dockerd cannot run.
# Usage: eval "$(bash docker/dockerd.sh)"; ... ; bash docker/dockerd.sh --stop
set -euo pipefail
state="${IDMS_DOCKER_STATE:-/var/tmp/idms-docker}"
sock="unix://$state/docker.sock"
docker_bin="${IDMS_DOCKER_CLIENT:-/usr/bin/docker}"

if [ "${1:-}" = "--stop" ]; then
  [ -f "$state/docker.pid" ] && kill "$(cat "$state/docker.pid")" 2>/dev/null || true
  exit 0
fi
if ! command -v dockerd >/dev/null; then
  echo "dockerd.sh: no dockerd (Debian's docker.io is not installed)" >&2
  exit 3
fi
mkdir -p "$state"
if ! DOCKER_HOST="$sock" "$docker_bin" info >/dev/null 2>&1; then
  # containerd comes with docker.io; dockerd starts its own when none runs.
  nohup dockerd --data-root "$state/root" --exec-root "$state/exec" --host "$sock" \
    --pidfile "$state/docker.pid" --bridge=none --iptables=false --ip-masq=false \
    > "$state/dockerd.log" 2>&1 &
  for _ in $(seq 1 100); do
    DOCKER_HOST="$sock" "$docker_bin" info >/dev/null 2>&1 && break
    sleep 0.2
  done
  if ! DOCKER_HOST="$sock" "$docker_bin" info >/dev/null 2>&1; then
    echo "dockerd.sh: dockerd did not start; its log ($state/dockerd.log) ends:" >&2
    tail -5 "$state/dockerd.log" >&2
    exit 3
  fi
fi
echo "export DOCKER_HOST=$sock"
