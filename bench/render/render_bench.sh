#!/usr/bin/env bash
# The renderer's figures: idms-render-bench (render and PNG medians), then the server's screenshot
# endpoint end to end (curl's time_total, loopback) for a 1280x720 image of a recorded session on
# a ~2x10^4-triangle slab: cold renders (each a new t, so never cached) and cache hits. Medians.
# Prints figures; fails only when a request fails. Usage: bench/render/render_bench.sh [BUILD_DIR] [--quick]
# One core: ONE_CPU=0 pins the bench and the server to CPU 0 (taskset) with LP_NUM_THREADS=0
# (llvmpipe rasterises on the calling thread).
set -euo pipefail
build=${1:-build}
quick=${2:-}
bin=$build/bin
reps=30
[ "$quick" = "--quick" ] && reps=5
tmp=$(mktemp -d)
server_pid=
trap '[ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null; wait 2>/dev/null || true; rm -rf "$tmp"' EXIT

pin=()
if [ -n "${ONE_CPU:-}" ]; then pin=(taskset -c "$ONE_CPU"); export LP_NUM_THREADS=0; fi
"${pin[@]}" "$bin/idms-render-bench" --reps "$reps"

# The server on a free port; a 100x100 slab (about 2x10^4 surface triangles) palpated for 2 s.
"${pin[@]}" "$bin/idms-server" --listen 127.0.0.1:0 --data "$tmp/data" > "$tmp/stdout" 2> "$tmp/server.log" &
server_pid=$!
for _ in $(seq 100); do grep -q listening "$tmp/stdout" 2>/dev/null && break; sleep 0.1; done
port=$(sed -n 's/.*:\([0-9]*\)$/\1/p' "$tmp/stdout" | head -1)
[ -n "$port" ] || { echo "render_bench: the server did not start" >&2; cat "$tmp/server.log" >&2; exit 1; }
admin=$(awk '$1=="admin"{print $2}' "$tmp/data/tokens")
agent=$(awk '$1=="agent"{print $2}' "$tmp/data/tokens")
observer=$(awk '$1=="observer"{print $2}' "$tmp/data/tokens")
base=http://127.0.0.1:$port
"$bin/idms-sim" generate slab --rows 100 --cols 100 --out "$tmp/slab" > /dev/null
curl -sf -o /dev/null -X PUT -H "Authorization: Bearer $admin" -F "fem=@$tmp/slab.fem" -F "plg=@$tmp/slab.plg" \
  "$base/api/models/bench_slab"
"$bin/idms-agent" --server "ws://127.0.0.1:$port" --token "$agent" --model bench_slab --device scripted:palpate \
  --duration 2 --no-realtime --cache-dir "$tmp/cache" > "$tmp/agent.log" 2>&1
id=
for _ in $(seq 100); do
  id=$(curl -sf -H "Authorization: Bearer $observer" "$base/api/sessions" |
    python3 -c 'import json,sys; s=json.load(sys.stdin)["sessions"]; print(s[0]["id"] if s and s[0]["state"]=="ended" else "")')
  [ -n "$id" ] && break; sleep 0.1
done
[ -n "$id" ] || { echo "render_bench: the session did not end" >&2; exit 1; }
triangles=$(curl -sf -H "Authorization: Bearer $observer" "$base/api/models/bench_slab" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["triangles"])')

# One request: "status time_total_ms server_timing".
shot() {
  curl -s -o /dev/null -D "$tmp/headers" -w '%{http_code} %{time_total}\n' -H "Authorization: Bearer $observer" \
    "$base/api/sessions/$id/screenshot.png?$1" > "$tmp/curl"
  read -r status seconds < "$tmp/curl"
  [ "$status" = 200 ] || { echo "render_bench: HTTP $status for ?$1" >&2; exit 1; }
  timing=$(tr -d '\r' < "$tmp/headers" | sed -n 's/^[Ss]erver-[Tt]iming: //p')
  echo "$(awk -v s="$seconds" 'BEGIN{printf "%.2f", s * 1000}') $timing"
}
median() { sort -g | awk '{v[NR]=$1} END{print v[int((NR+1)/2)]}'; }
: > "$tmp/cold"; : > "$tmp/render"; : > "$tmp/png"; : > "$tmp/load"; : > "$tmp/total"; : > "$tmp/hit"
for i in $(seq "$reps"); do
  line=$(shot "t=$(awk -v i="$i" -v n="$reps" 'BEGIN{printf "%.4f", 1.9 * i / n}')&size=1280x720")
  echo "$line" | awk '{print $1}' >> "$tmp/cold"
  echo "$line" | sed -n 's/.*render;dur=\([0-9.]*\).*/\1/p' >> "$tmp/render"
  echo "$line" | sed -n 's/.*png;dur=\([0-9.]*\).*/\1/p' >> "$tmp/png"
  echo "$line" | sed -n 's/.*load;dur=\([0-9.]*\).*/\1/p' >> "$tmp/load"
  echo "$line" | sed -n 's/.*total;dur=\([0-9.]*\).*/\1/p' >> "$tmp/total"
  shot "t=$(awk -v i="$i" -v n="$reps" 'BEGIN{printf "%.4f", 1.9 * i / n}')&size=1280x720" | awk '{print $1}' >> "$tmp/hit"
done
where="$(nproc) cores"; [ -n "${ONE_CPU:-}" ] && where="CPU $ONE_CPU only, LP_NUM_THREADS=0"
echo "screenshot endpoint, 1280x720, $triangles triangles, server on $where (shared with other work), medians of $reps:"
echo "  end to end (curl, cold render): $(median < "$tmp/cold") ms   [handler $(median < "$tmp/total") ms: recording read $(median < "$tmp/load"), render $(median < "$tmp/render"), png $(median < "$tmp/png")]"
echo "  end to end (cache hit):         $(median < "$tmp/hit") ms"
