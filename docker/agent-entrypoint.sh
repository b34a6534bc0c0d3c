#!/bin/sh
# idms-agent in a container: publishes to $IDMS_SERVER (ws://HOST:PORT) with the agent token from
# $IDMS_AGENT_TOKEN, or else from the server's tokens file ($IDMS_TOKENS_FILE, the server's data
# volume mounted read-only). Arguments go to idms-agent (default: the scripted palpation).
set -eu
server="${IDMS_SERVER:-ws://127.0.0.1:8080}"
token="${IDMS_AGENT_TOKEN:-}"
if [ -z "$token" ] && [ -n "${IDMS_TOKENS_FILE:-}" ]; then
  # The server writes the file at its first start: wait for it.
  for _ in $(seq 1 150); do [ -s "$IDMS_TOKENS_FILE" ] && break; sleep 0.2; done
  token=$(awk '$1 == "agent" && $2 !~ /^sha256:/ {print $2; exit}' "$IDMS_TOKENS_FILE")
fi
[ -n "$token" ] || { echo "idms-agent-entrypoint: no agent token (set IDMS_AGENT_TOKEN or IDMS_TOKENS_FILE)" >&2; exit 2; }
[ "$#" -gt 0 ] || set -- --model hex_4x5_home --device scripted:palpate --duration 3
exec idms-agent --server "$server" --token "$token" --no-realtime --cache-dir /var/lib/idms/cache "$@"
