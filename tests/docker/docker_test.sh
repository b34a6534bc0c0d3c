#!/usr/bin/env bash
# The compose stack end to end (docker/): builds the three images from the sources, brings the
# server, the agent and the renderer up on the host's network, and checks through the server's
# port: /api/health and the container's own HEALTHCHECK, a non-root server, a recorded session
# read back whole by the independent MCAP reader, the renderer's screenshot and the server's.
# Exit 77 (CTest: skipped) only where dockerd cannot run, saying why.
# Usage: tests/docker/docker_test.sh SOURCE_DIR WORK_DIR
set -euo pipefail
src=$(cd "$1" && pwd)
work=$2
rm -rf "$work" && mkdir -p "$work/shots"
chmod 0777 "$work/shots"  # written by the renderer's non-root user

if ! env_line=$(bash "$src/docker/dockerd.sh" 2> "$work/dockerd.err"); then
  echo "SKIPPED: dockerd cannot run on this machine: $(cat "$work/dockerd.err")"
  exit 77
fi
eval "$env_line"
docker="${IDMS_DOCKER_CLIENT:-/usr/bin/docker}"
bash "$src/docker/base-image.sh"

export DOCKER_BUILDKIT=1
start=$(date +%s)
for target in server agent render; do
  "$docker" build -q --network host -f "$src/docker/Dockerfile" --target "$target" -t "idms-$target:local" "$src" \
    > "$work/build-$target.log" 2>&1 || { tail -40 "$work/build-$target.log"; exit 1; }
done
echo "images built in $(( $(date +%s) - start )) s"

# A free loopback port (nothing answers a connect there).
port=""
for _ in $(seq 50); do
  p=$(( 20000 + RANDOM % 40000 ))
  if ! (exec 3<> "/dev/tcp/127.0.0.1/$p") 2>/dev/null; then port=$p; break; fi
done
[ -n "$port" ] || { echo "no free port"; exit 1; }

project="idms-test-$$"
compose=(docker-compose -p "$project" -f "$src/docker/compose.yaml")
export IDMS_PORT=$port IDMS_SCREENSHOTS="$work/shots"
down() {
  "${compose[@]}" logs --no-color > "$work/compose.log" 2>&1 || true
  "${compose[@]}" down -v > /dev/null 2>&1 || true
}
trap down EXIT
"${compose[@]}" up -d --no-build > "$work/up.log" 2>&1 || { cat "$work/up.log"; exit 1; }
url="http://127.0.0.1:$port"

# "W x H" of a PNG file (from its IHDR), or nothing when it is no PNG.
png_size() {
  [ "$(od -An -tx1 -N8 "$1" | tr -d ' \n')" = 89504e470d0a1a0a ] || return 0
  local b=($(od -An -tu1 -j16 -N8 "$1"))
  echo "$(( (b[0] << 24) | (b[1] << 16) | (b[2] << 8) | b[3] )) x $(( (b[4] << 24) | (b[5] << 16) | (b[6] << 8) | b[7] ))"
}
fail() { echo "FAIL: $*"; down; tail -30 "$work/compose.log"; exit 1; }
eventually() {  # SECONDS COMMAND...: until the command succeeds
  local until=$(( $(date +%s) + $1 )); shift
  until "$@" > /dev/null 2>&1; do [ "$(date +%s)" -lt "$until" ] || return 1; sleep 0.5; done
}

eventually 60 curl -fsS "$url/api/health" || fail "no /api/health on the published port $port"
curl -fsS "$url/api/health"; echo
server_container=$("${compose[@]}" ps -q server)
healthy() { [ "$("$docker" inspect -f '{{.State.Health.Status}}' "$server_container")" = healthy ]; }
eventually 60 healthy || fail "the server's HEALTHCHECK did not report healthy"
uid=$("${compose[@]}" exec -T server id -u)
[ "$uid" != 0 ] || fail "the server runs as root"
observer=$("${compose[@]}" exec -T server awk '$1 == "observer" {print $2}' /var/lib/idms/tokens)
[ -n "$observer" ] || fail "no observer token in the server's data volume"

ended_id() {
  curl -fsS -H "Authorization: Bearer $observer" "$url/api/sessions" | tr '{' '\n' | grep '"state":"ended"' |
    sed -n 's/.*"id":"\([^"]*\)".*/\1/p' | head -1
}
eventually 120 test -n "$(ended_id)" || fail "no recorded session"
id=$(ended_id)
curl -fsS -H "Authorization: Bearer $observer" -o "$work/session.mcap" "$url/api/sessions/$id/recording.mcap"
node "$src/tests/mcap-js/check_recording.mjs" "$work/session.mcap" --expect-ticks 3000 ||
  fail "the recording of session $id is not whole"

# The renderer's screenshot, on the mounted directory: a PNG of the requested size.
eventually 120 test -s "$work/shots/$id.png" || fail "no screenshot from the renderer"
[ "$(png_size "$work/shots/$id.png")" = "1280 x 720" ] || fail "the renderer's screenshot: $(png_size "$work/shots/$id.png")"
# The server renders one too, through the published port.
code=$(curl -s -o "$work/server-shot.png" -w '%{http_code}' -H "Authorization: Bearer $observer" \
  "$url/api/sessions/$id/screenshot.png?t=2.5&size=640x360")
[ "$code" = 200 ] || fail "GET screenshot.png: HTTP $code"
[ "$(png_size "$work/server-shot.png")" = "640 x 360" ] || fail "the server's screenshot: $(png_size "$work/server-shot.png")"
echo "docker: health, non-root, session $id recorded whole, screenshots from idms-render and the server"
