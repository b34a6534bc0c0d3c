#!/usr/bin/env bash
# The whole system on this machine: installs and builds, starts idms-server (an empty temporary
# data directory unless --data is given: it imports the shipped models and writes a token per
# role), lets idms-agent palpate, stroke and pluck the thesis fragment (figure 3-1, fetched from
# the server's library by name; each a recorded session), shows a broken upload refused at its
# line, renders the palpation's dent with idms-render, then keeps a live session running and
# prints where to watch it in the browser and what to log in with, until Ctrl-C or --duration.
#
# Usage: scripts/demo.sh [--headless] [--duration SECONDS] [--port N] [--data DIR] [--no-build]
#   --headless   nothing to watch: the scripted sessions, the screenshots, the figures, then exit
#                (what CI runs; implies --duration 0)
#   --duration   seconds to keep the live session and the server up (default: until Ctrl-C)
#   --port       the server's port on 127.0.0.1 (default 8740, or a free one if it is taken)
#   --no-build   use build/bin as it is
set -euo pipefail
cd "$(dirname "$0")/.."

headless=false build=true duration="" port=8740 data=""
while (($#)); do
  case "$1" in
    --headless) headless=true ;;
    --duration) duration="$2"; shift ;;
    --port) port="$2"; shift ;;
    --data) data="$2"; shift ;;
    --no-build) build=false ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) echo "demo: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
$headless && duration=0

$build && bash scripts/build.sh
bin=build/bin
out=build/demo
rm -rf "$out" && mkdir -p "$out"
[ -n "$data" ] || data=$(mktemp -d -t idms-demo-XXXXXX)

pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT
trap 'echo; echo "demo: stopping"; exit 0' INT TERM

start_server() {  # $1: listen address
  "$bin/idms-server" --listen "$1" --data "$data" > "$out/server.out" 2> "$out/server.log" &
  server_pid=$!
  for _ in $(seq 100); do
    grep -q "listening on" "$out/server.out" 2>/dev/null && return 0
    kill -0 "$server_pid" 2>/dev/null || return 1
    sleep 0.1
  done
  return 1
}
echo "== idms-server (data: $data)"
if ! start_server "127.0.0.1:$port"; then
  echo "demo: port $port is taken; using a free one"
  start_server "127.0.0.1:0" || { cat "$out/server.log"; exit 1; }
fi
pids+=("$server_pid")
url=$(sed -n 's/^idms-server listening on //p' "$out/server.out")
admin=$(awk '$1 == "admin" {print $2}' "$data/tokens")
agent=$(awk '$1 == "agent" {print $2}' "$data/tokens")
observer=$(awk '$1 == "observer" {print $2}' "$data/tokens")
echo "$url; the library:"
curl -sf -H "Authorization: Bearer $observer" "$url/api/models" | tr '{' '\n' | sed -n 's/.*"name":"\([^"]*\)".*/  \1/p'
echo

echo "== a malformed model is refused at its line, and nothing is stored"
sed 's/^0.5 0 0 0.002 1001 2001$/0.5 0 nan 0.002 1001 2001/' models/hex_4x5_home.fem > "$out/broken.fem"
curl -s -H "Authorization: Bearer $admin" -X PUT -F fem=@"$out/broken.fem" -F plg=@models/hex_4x5_home.plg \
  "$url/api/models/broken_fragment"; echo

# One recorded session per interaction of thesis chapter 6, the model fetched by name.
ws="ws://${url#http://}"
# Each for its script's length (thesis figures 6-2, 6-6 and 6-8; the fast stroke at the thesis's speed);
# then a needle's pierce (thesis 7.2.4: in at a slant, held, and out, docs/needle.md) and a stitch
# (a needle drawn down through the fragment, its thread left in and tied).
for run in palpate:5.5 stroke-fast:5.8 pluck:5 pierce:12 stitch:14; do
  script=${run%%:*} seconds=${run#*:}
  echo "== idms-agent: $script on hex_4x5_home, $seconds s at 1 kHz, published and recorded"
  "$bin/idms-agent" --server "$ws" --token "$agent" --model hex_4x5_home --device "scripted:$script" \
    --duration "$seconds" --no-realtime --cache-dir "$out/agent-cache" --summary-json "$out/$script.json" \
    > "$out/agent-$script.log" 2>&1
  id=$(sed -n 's/.*"session_id": *"\([^"]*\)".*/\1/p' "$out/$script.json")
  curl -sf -H "Authorization: Bearer $observer" -o "$out/$script.mcap" "$url/api/sessions/$id/recording.mcap"
  echo "   session $id: $(sed -n 's/.*"ticks": *\([0-9]*\).*/\1/p' "$out/$script.json") ticks," \
    "recording $out/$script.mcap ($(stat -c %s "$out/$script.mcap") bytes)"
  eval "id_${script//-/_}=$id"
done

# The suture (docs/needle.md, "The scripted suture"): the scalpel opens an incision through a soft
# slab, then three stitches across it are tied; its 98 s at five times real time.
echo "== idms-agent: a suture on suture_slab (models/suture.scene), 100 s at 5 kHz (5x real time), recorded"
"$bin/idms-agent" --server "$ws" --token "$agent" --model suture_slab --scene models/suture.scene \
  --device scripted:suture --rate 5000 --duration 20 --no-realtime --cache-dir "$out/agent-cache" \
  --summary-json "$out/suture.json" > "$out/agent-suture.log" 2>&1
id_suture=$(sed -n 's/.*"session_id": *"\([^"]*\)".*/\1/p' "$out/suture.json")
curl -sf -H "Authorization: Bearer $observer" -o "$out/suture.mcap" "$url/api/sessions/$id_suture/recording.mcap"
echo "   session $id_suture: recording $out/suture.mcap ($(stat -c %s "$out/suture.mcap") bytes)"

echo "== idms-render: the palpation at t = 2.5 s, the pluck lifting the tissue at 3.5 s, the needle in at 5 s,"
echo "   the stitch tied at 12 s, the suture closed at 97 s, the tissue at rest"
"$bin/idms-render" --recording "$out/palpate.mcap" --at 2.5 --size 1280x720 --show-tool --show-force \
  --out "$out/palpate.png"
"$bin/idms-render" --model models/hex_4x5_home --size 1280x720 --out "$out/rest.png"
"$bin/idms-render" --recording "$out/pluck.mcap" --at 3.5 --size 1280x720 --camera 2,-3.2,1.6:2,1.7,0 \
  --out "$out/pluck.png"
"$bin/idms-render" --recording "$out/pierce.mcap" --at 5 --size 1280x720 --show-tool --show-force \
  --out "$out/pierce.png"
"$bin/idms-render" --recording "$out/stitch.mcap" --at 12 --size 1280x720 --show-tool --camera 6,-5,3:1.5,1.7,-1.5 \
  --out "$out/stitch.png"
"$bin/idms-render" --recording "$out/suture.mcap" --at 97 --size 1280x720 --show-tool --camera 6.2,-1,6:6.2,4.3,0 \
  --out "$out/suture.png"
ls -l "$out"/*.png | awk '{print "   " $NF " (" $5 " bytes)"}'

if $headless; then
  echo "== headless: done. Recordings and screenshots in $out/, server log $out/server.log"
  exit 0
fi

echo "== a live session to watch: a simulated hand stroking the fragment gently (one crossing in 4 s)"
"$bin/idms-agent" --server "$ws" --token "$agent" --model hex_4x5_home --device human:stroke-gentle \
  --duration "${duration:-0}" --no-realtime --cache-dir "$out/agent-cache" > "$out/agent-live.log" 2>&1 &
pids+=("$!")
live=""
for _ in $(seq 100); do
  live=$(curl -sf -H "Authorization: Bearer $observer" "$url/api/sessions" | tr '{' '\n' |
         grep '"state":"live"' | sed -n 's/.*"id":"\([^"]*\)".*/\1/p' | head -1) || true
  [ -n "$live" ] && break
  sleep 0.1
done
cat <<MSG

  Open in a browser:   $url/login
    log in with the admin token:    $admin
    (or the observer token:         $observer)
  The live session:    $url/session/$live
  Replays:             $url/replay/$id_palpate?t=2.5   (palpation)
                       $url/replay/$id_pluck           (pluck)
                       $url/replay/$id_pierce?t=5      (a needle's pierce)
                       $url/replay/$id_stitch?t=12     (a stitch, its thread tied)
                       $url/replay/$id_suture?t=97     (an incision closed by three stitches)
  The model library:   $url/models
  Screenshots:         $out/palpate.png, $out/pluck.png, $out/pierce.png, $out/stitch.png, $out/suture.png, $out/rest.png
  Recordings:          $out/*.mcap (and $data/recordings/)
  Tokens:              $data/tokens

MSG
if [ -n "$duration" ] && [ "$duration" != 0 ]; then
  echo "demo: running for $duration s"
  sleep "$duration"
else
  echo "demo: running until Ctrl-C"
  wait "$server_pid"
fi
