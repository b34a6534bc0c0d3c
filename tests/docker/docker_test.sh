#!/usr/bin/env bash
# The compose stack end to end (docker/): builds the three images from the sources, brings the
# server, the agent and the renderer up on the host's network, and checks through the server's
# port: /api/health and the container's own HEALTHCHECK, a non-root server, a recorded session
# read back whole by the independent MCAP reader, the renderer's screenshot and the server's.
# Then the several-servers stack (docker/compose.scale.yaml: PostgreSQL, three NATS, Swift, three
# idms-servers, HAProxy, an agent) from a clean start: every server healthy, the library's blobs
# and the live session's recording in Swift's bucket, the session watched through HAProxy, and
# watched on a server that does not own it (relayed over NATS).
# Exit 77 (CTest: skipped) only where dockerd cannot run, saying why.
# Usage: tests/docker/docker_test.sh SOURCE_DIR WORK_DIR [BUILD_DIR]
# With BUILD_DIR (as CTest runs it) the images take the programs built there (the Dockerfile's
# PROGRAMS=host); IDMS_DOCKER_PROGRAMS=source, or no BUILD_DIR, compiles them in the image instead.
set -euo pipefail
src=$(cd "$1" && pwd)
work=$2
build_dir=${3:-}
programs=${IDMS_DOCKER_PROGRAMS:-$([ -n "$build_dir" ] && echo host || echo source)}
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
# The machine's CA bundle for npm inside the build (this network's proxy re-signs TLS).
secret=()
ca=/etc/ssl/certs/ca-certificates.crt
[ -s "$ca" ] && secret=(--secret "id=ca,src=$ca")
start=$(date +%s)
context=$src
if [ "$programs" = host ]; then
  # A context of what the runtime stages copy: the models, the entry points, and the programs
  # from BUILD_DIR, stripped as the source stage strips them.
  context=$work/context
  mkdir -p "$context/docker" "$context/programs/bin"
  cp -r "$src/models" "$context/models"
  cp "$src/docker/"*-entrypoint.sh "$src/docker/"*-config.sh "$context/docker/"
  for p in idms-server idms-agent idms-render; do
    [ -x "$build_dir/bin/$p" ] || { echo "FAIL: no $build_dir/bin/$p (build it first)"; exit 1; }
    strip -o "$context/programs/bin/$p" "$build_dir/bin/$p"
  done
  [ -f "$build_dir/web/index.html" ] || { echo "FAIL: no web viewer in $build_dir/web"; exit 1; }
  cp -r "$build_dir/web" "$context/programs/web"
fi
for target in server agent render postgres nats haproxy swift; do
  "$docker" build -q --network host "${secret[@]}" -f "$src/docker/Dockerfile" --target "$target" \
    --build-arg "PROGRAMS=$programs" -t "idms-$target:local" "$context" \
    > "$work/build-$target.log" 2>&1 || { tail -40 "$work/build-$target.log"; exit 1; }
done
echo "images built in $(( $(date +%s) - start )) s (programs: $programs)"

# Free loopback ports (nothing answers a connect there), below the kernel's ephemeral range: a
# port there may be the local end of some other program's connection, and a server's bind fails.
ephemeral_low=$(cut -f1 /proc/sys/net/ipv4/ip_local_port_range 2>/dev/null || echo 32768)
taken=" "
free_port() {  # VAR: a free port, never one handed out before, into VAR
  local p
  for _ in $(seq 200); do
    p=$(( 10000 + RANDOM % (ephemeral_low - 10000) ))
    case "$taken" in *" $p "*) continue ;; esac
    if ! (exec 3<> "/dev/tcp/127.0.0.1/$p") 2>/dev/null; then taken="$taken$p "; printf -v "$1" %s "$p"; return; fi
  done
  echo "no free port" >&2; exit 1
}
free_port port

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

# STATE: the id of the newest session in that state at $url, or nothing.
session_in() {
  curl -fsS -H "Authorization: Bearer $observer" "$url/api/sessions" | tr '{' '\n' | grep "\"state\":\"$1\"" |
    sed -n 's/.*"id":"\([^"]*\)".*/\1/p' | awk 'NR == 1'
}
# Whether there is a session in STATE (evaluated on every attempt of `eventually`).
has_session() { [ -n "$(session_in "$1")" ]; }
eventually 120 has_session ended || fail "no recorded session"
id=$(session_in ended)
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

# ---- several servers (docker/compose.scale.yaml), from a clean start ---------------------------
down
trap - EXIT
for v in IDMS_PORT IDMS_PG_PORT IDMS_SERVER_PORT_1 IDMS_SERVER_PORT_2 IDMS_SERVER_PORT_3 IDMS_NATS_PORT_1 \
  IDMS_NATS_PORT_2 IDMS_NATS_PORT_3 IDMS_NATS_ROUTE_1 IDMS_NATS_ROUTE_2 IDMS_NATS_ROUTE_3 IDMS_S3_PORT \
  IDMS_SWIFT_ACCOUNT_PORT IDMS_SWIFT_CONTAINER_PORT IDMS_SWIFT_OBJECT_PORT; do
  free_port "$v"
  export "$v"
done
export IDMS_AGENT_SECONDS=120
# Credentials of the test's own, so that the stack is seen to take them from the environment.
export IDMS_S3_ACCESS_KEY="idms:test-$$" IDMS_S3_SECRET_KEY="secret-$RANDOM$RANDOM"
# curl's (its --user splits at the first colon, and the key holds one).
(umask 077 && echo "machine 127.0.0.1 login $IDMS_S3_ACCESS_KEY password $IDMS_S3_SECRET_KEY" > "$work/netrc")
compose=(docker-compose -p "$project-scale" -f "$src/docker/compose.scale.yaml")
work_log=$work/compose-scale.log
down() {
  "${compose[@]}" logs --no-color > "$work_log" 2>&1 || true
  "${compose[@]}" down -v > /dev/null 2>&1 || true
}
fail() { echo "FAIL: $*"; down; tail -40 "$work_log"; exit 1; }
trap down EXIT
start=$(date +%s)
"${compose[@]}" up -d --no-build > "$work/up-scale.log" 2>&1 || fail "up: $(tail -20 "$work/up-scale.log")"
servers=("$IDMS_SERVER_PORT_1" "$IDMS_SERVER_PORT_2" "$IDMS_SERVER_PORT_3")
for p in "${servers[@]}"; do
  eventually 120 curl -fsS "http://127.0.0.1:$p/api/health" || fail "no /api/health on server port $p"
done
url="http://127.0.0.1:$IDMS_PORT"
eventually 60 curl -fsS "$url/api/health" || fail "no /api/health through HAProxy ($url)"
echo "scale: 3 servers healthy, HAProxy answering, $(( $(date +%s) - start )) s after up"
# S3 through Swift's API as any client reaches it, signed by curl itself (SigV4).
s3() {  # CURL_ARGS... PATH: curl on the stack's bucket
  local path=${*: -1}
  curl -fsS --max-time 10 --aws-sigv4 aws:amz:us-east-1:s3 --netrc-file "$work/netrc" \
    -H 'x-amz-content-sha256: UNSIGNED-PAYLOAD' "${@:1:$#-1}" "http://127.0.0.1:$IDMS_S3_PORT/idms$path"
}
s3_keys() {  # PREFIX (letters, digits, -, /): the keys under PREFIX, one a line (ListObjectsV2)
  # The query as SigV4 signs it, canonical (curl 7.88 signs it as given): the prefix's / encoded.
  local listing
  listing=$(s3 "?list-type=2&prefix=${1//\//%2F}") || return 1
  { grep -o '<Key>[^<]*</Key>' <<< "$listing" || true; } | sed 's/<[^>]*>//g'
}
has_keys() { [ -n "$(s3_keys "$1")" ]; }
blob_keys=$(s3_keys blobs/) || fail "no listing of Swift's bucket on :$IDMS_S3_PORT"
blobs=$(grep -c . <<< "$blob_keys" || true)
[ "$blobs" -gt 0 ] || fail "no model blob in Swift's bucket (the library seeded with --blobs)"
observer=$("${compose[@]}" exec -T server-1 awk '$1 == "observer" {print $2}' /var/lib/idms/server-1/tokens)
[ -n "$observer" ] || fail "no observer token on the shared volume"
eventually 120 has_session live || fail "no live session (the agent through HAProxy)"
id=$(session_in live)
# Its owner: the server where it is live.
owner=""
# The whole body first: `curl | grep -q` fails under pipefail when grep stops reading early.
live_on() {
  local metrics
  metrics=$(curl -fsS -H "Authorization: Bearer $observer" "http://127.0.0.1:$1/metrics") || return 1
  grep -qx 'idms_live_sessions 1' <<< "$metrics"
}
for p in "${servers[@]}"; do live_on "$p" && owner=$p; done
[ -n "$owner" ] || fail "session $id is live on no server"
# Each server writes in its own data directory on the shared volume: the session's local files
# are the owner's alone (a server that lost a session must not touch the new owner's file).
owner_dir=""
for n in 1 2 3; do [ "${servers[n - 1]}" = "$owner" ] && owner_dir=/var/lib/idms/server-$n; done
local_files=$("${compose[@]}" exec -T server-1 find /var/lib/idms -name "$id*")
[ -n "$local_files" ] || fail "no local file of session $id on the volume"
while read -r f; do
  case $f in "$owner_dir"/*) ;; *) fail "session $id has a file outside its owner's directory $owner_dir: $f" ;; esac
done <<< "$local_files"
echo "scale: session $id's local files all in its owner's $owner_dir: $(tr '\n' ' ' <<< "$local_files")"
# Its recording in the bucket: segments uploaded every second while live (recordings/ID/...), or
# the whole file once ended (recordings/ID.mcap); the first key is its start, an MCAP file's.
eventually 60 has_keys "recordings/$id" || fail "no recording of session $id in Swift's bucket"
keys=$(s3_keys "recordings/$id") || fail "no listing of Swift's bucket on :$IDMS_S3_PORT"
first=$(head -1 <<< "$keys")
s3 -o "$work/segment" "/$first" || fail "GET $first from Swift"
[ "$(od -An -tx1 -N8 "$work/segment" | tr -d ' \n')" = 894d434150300d0a ] ||
  fail "$first does not begin as an MCAP file"
# Watched through HAProxy (idms-render as a live viewer), then on a server that does not own it.
render=("$build_dir/bin/idms-render")
[ -x "${render[0]}" ] || render=("$docker" run --rm --network host -v "$work/shots:/out" --entrypoint idms-render idms-render:local)
out_dir=$work/shots
[ -x "$build_dir/bin/idms-render" ] || out_dir=/out
IDMS_TOKEN=$observer "${render[@]}" --server "$url" --session "$id" --out "$out_dir/scale-haproxy.png" --size 320x180 \
  > "$work/render-haproxy.log" 2>&1 || fail "idms-render through HAProxy: $(tail -5 "$work/render-haproxy.log")"
[ "$(png_size "$work/shots/scale-haproxy.png")" = "320 x 180" ] || fail "no screenshot of the live session through HAProxy"
other=""
for p in "${servers[@]}"; do [ "$p" != "$owner" ] && other=$p; done
IDMS_TOKEN=$observer "${render[@]}" --server "http://127.0.0.1:$other" --session "$id" \
  --out "$out_dir/scale-relayed.png" --size 320x180 > "$work/render-relayed.log" 2>&1 ||
  fail "idms-render on server $other (not the owner $owner): $(tail -5 "$work/render-relayed.log")"
[ "$(png_size "$work/shots/scale-relayed.png")" = "320 x 180" ] || fail "no screenshot of the session relayed"
relayed=$(curl -fsS -H "Authorization: Bearer $observer" "http://127.0.0.1:$other/metrics" |
  sed -n 's/^idms_relay_frames_relayed_total \([0-9]*\).*/\1/p')
[ "${relayed:-0}" -gt 0 ] || fail "server $other relayed no frame of session $id"
echo "docker scale: session $id owned by :$owner, watched through HAProxy and relayed by :$other ($relayed frames);" \
  "in Swift: $blobs blobs; recording objects so far: $(wc -l <<< "$keys"), the first an MCAP file's start" \
  "($first, $(stat -c %s "$work/segment") bytes)"
