#!/bin/sh
# idms-render in a container: waits for the newest ended session on $IDMS_HTTP, downloads its
# recording and renders it at $IDMS_RENDER_AT seconds to $IDMS_RENDER_OUT (a mounted directory).
# The token: $IDMS_TOKEN, or the observer's from $IDMS_TOKENS_FILE. With arguments, runs
# idms-render with them instead.
set -eu
[ "$#" -eq 0 ] || exec idms-render "$@"
http="${IDMS_HTTP:-http://127.0.0.1:8080}"
out="${IDMS_RENDER_OUT:-/out}"
token="${IDMS_TOKEN:-}"
if [ -z "$token" ] && [ -n "${IDMS_TOKENS_FILE:-}" ]; then
  for _ in $(seq 1 150); do [ -s "$IDMS_TOKENS_FILE" ] && break; sleep 0.2; done
  token=$(awk '$1 == "observer" && $2 !~ /^sha256:/ {print $2; exit}' "$IDMS_TOKENS_FILE")
fi
id=""
for _ in $(seq 1 300); do
  # The list is newest first; the first "id" whose entry says "ended".
  id=$(curl -fsS -H "Authorization: Bearer $token" "$http/api/sessions" 2>/dev/null |
       tr '{' '\n' | grep '"state":"ended"' | sed -n 's/.*"id":"\([^"]*\)".*/\1/p' | head -1) || true
  [ -n "$id" ] && break
  sleep 1
done
[ -n "$id" ] || { echo "idms-render-entrypoint: no ended session on $http" >&2; exit 1; }
curl -fsS -H "Authorization: Bearer $token" -o /tmp/session.mcap "$http/api/sessions/$id/recording.mcap"
idms-render --recording /tmp/session.mcap --at "${IDMS_RENDER_AT:-2.5}" --size "${IDMS_RENDER_SIZE:-1280x720}" \
  --show-tool --show-force --out "$out/$id.png"
echo "idms-render-entrypoint: $out/$id.png"
