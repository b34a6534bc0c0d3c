#!/usr/bin/env bash
# idms-server under load, measured with wrk (Debian) on loopback: requests per second and p50/p99
# latency of GET /api/models, of a download of a named (immutable) version, and of its 304
# revalidation, at 1, 16 and 64 connections; then the upload-and-validate time of a large model
# (10^6 atoms by default), median of three. Prints a table and writes CSV. Never fails on time.
# Usage: bench/server/server_bench.sh [BUILD_DIR] [--quick]   (quick: 1 s per point, 10^4 atoms)
set -euo pipefail
build=${1:-build}
quick=${2:-}
bin=$build/bin
seconds=5; rows=577; cols=577   # 577 x 577 top grid: 1,000,040 atoms
if [ "$quick" = "--quick" ]; then seconds=1; rows=58; cols=58; fi
out=$build/bench/server
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'kill "$server_pid" 2>/dev/null || true; wait 2>/dev/null || true; rm -rf "$tmp"' EXIT

# The server on a free port, with its shipped library; its first line names the port.
"$bin/idms-server" --listen 127.0.0.1:0 --data "$tmp/data" --max-upload-mb 1024 > "$tmp/stdout" 2> "$tmp/server.log" &
server_pid=$!
for _ in $(seq 100); do grep -q listening "$tmp/stdout" 2>/dev/null && break; sleep 0.1; done
[ -s "$tmp/stdout" ] || { echo "server_bench: the server did not start" >&2; cat "$tmp/server.log" >&2; exit 1; }
port=$(sed -n 's/.*:\([0-9]*\)$/\1/p' "$tmp/stdout" | head -1)
admin=$(awk '$1=="admin"{print $2}' "$tmp/data/tokens")
observer=$(awk '$1=="observer"{print $2}' "$tmp/data/tokens")
base=http://127.0.0.1:$port
etag=$(curl -sfI -H "Authorization: Bearer $observer" "$base/api/models/hex_4x5_home/fem?version=1" |
  tr -d '\r' | sed -n 's/^[Ee][Tt]ag: //p')

echo "idms-server bench: $(nproc) cores shared by server ($(grep -c ^processor /proc/cpuinfo) hw threads) and wrk; ${seconds}s per point"
csv=$out/http.csv
echo "endpoint,connections,requests_per_s,p50_ms,p99_ms,server_cpu_us_per_request" > "$csv"
printf '%-34s %5s %12s %9s %9s %14s\n' endpoint conns "req/s" "p50 ms" "p99 ms" "server cpu us"
# The server's CPU time (user + system, clock ticks) from /proc, to divide by the requests served.
cpu_ticks() { awk '{print $14 + $15}' "/proc/$server_pid/stat"; }
hz=$(getconf CLK_TCK)
# wrk --latency prints "50%  1.23ms"; normalise us/ms/s to ms.
to_ms() { awk '{v=$1; if (v ~ /us$/) {sub(/us$/,"",v); v/=1000} else if (v ~ /ms$/) {sub(/ms$/,"",v)} else if (v ~ /s$/) {sub(/s$/,"",v); v*=1000}; printf "%.3f", v}'; }
run() {  # name path conns [extra header]
  local name=$1 path=$2 conns=$3 extra=${4:-}
  local threads=$(( conns < 2 ? 1 : 2 ))
  local args=(-t"$threads" -c"$conns" -d"${seconds}s" --latency -H "Authorization: Bearer $observer")
  [ -n "$extra" ] && args+=(-H "$extra")
  local c0 c1
  c0=$(cpu_ticks)
  wrk "${args[@]}" "$base$path" > "$tmp/wrk.txt"
  c1=$(cpu_ticks)
  local rps p50 p99 requests cpu_us
  rps=$(awk '/^Requests\/sec/{print $2}' "$tmp/wrk.txt")
  p50=$(awk '$1=="50%"{print $2}' "$tmp/wrk.txt" | to_ms)
  p99=$(awk '$1=="99%"{print $2}' "$tmp/wrk.txt" | to_ms)
  requests=$(awk '/requests in/{print $1}' "$tmp/wrk.txt")
  cpu_us=$(awk -v a="$c0" -v b="$c1" -v hz="$hz" -v n="$requests" 'BEGIN{printf "%.1f", (b - a) / hz * 1e6 / n}')
  if [ -z "$rps" ] || [ -z "$p50" ] || [ -z "$p99" ] || { grep -q "Non-2xx" "$tmp/wrk.txt" && [ "$name" != "fem_304" ]; }; then
    echo "server_bench: no figures or non-2xx answers on $path" >&2; cat "$tmp/wrk.txt" >&2; exit 1
  fi
  printf '%-34s %5d %12.0f %9s %9s %14s\n' "$name" "$conns" "$rps" "$p50" "$p99" "$cpu_us"
  echo "$name,$conns,$rps,$p50,$p99,$cpu_us" >> "$csv"
}
for c in 1 16 64; do run list_models /api/models "$c"; done
for c in 1 16 64; do run fem_download_v1 "/api/models/hex_4x5_home/fem?version=1" "$c"; done
for c in 1 16 64; do run fem_304 "/api/models/hex_4x5_home/fem?version=1" "$c" "If-None-Match: $etag"; done

# A large model: generate, then upload with curl three times (each a new version), median.
"$bin/idms-sim" generate slab --rows "$rows" --cols "$cols" --out "$tmp/big" > /dev/null
atoms=$(head -1 "$tmp/big.fem" | awk '{print $2}')
bytes=$(( $(stat -c %s "$tmp/big.fem") + $(stat -c %s "$tmp/big.plg") ))
times=()
for i in 1 2 3; do
  t=$(curl -sf -o /dev/null -w '%{time_total}' -X PUT -H "Authorization: Bearer $admin" \
    -F "fem=@$tmp/big.fem" -F "plg=@$tmp/big.plg" "$base/api/models/big")
  times+=("$t")
done
[ ${#times[@]} -eq 3 ] || { echo "server_bench: an upload failed" >&2; exit 1; }
median=$(printf '%s\n' "${times[@]}" | sort -g | sed -n 2p)
# The server's own time for the same requests (body read, parse, validate, store), from its log.
server_ms=$(grep 'method=PUT path=/api/models/big ' "$tmp/server.log" | sed -n 's/.* ms=\([0-9.]*\).*/\1/p' | sort -g | sed -n 2p)
parse_ms=$(grep 'model stored name=big ' "$tmp/server.log" | sed -n 's/.* parse_ms=\([0-9.]*\).*/\1/p' | sort -g | sed -n 2p)
store_ms=$(grep 'model stored name=big ' "$tmp/server.log" | sed -n 's/.* store_ms=\([0-9.]*\).*/\1/p' | sort -g | sed -n 2p)
echo "upload+validate: $atoms atoms, $bytes bytes (fem+plg), curl -F: median ${median} s of ${times[*]}"
echo "  server side (medians): whole request ${server_ms} ms = body read and multipart split, then parse+validate+obj ${parse_ms} ms, hash+write+fsync+commit ${store_ms} ms"
echo "atoms,bytes,upload_median_s,server_median_ms,parse_median_ms,store_median_ms" > "$out/upload.csv"
echo "$atoms,$bytes,$median,$server_ms,$parse_ms,$store_ms" >> "$out/upload.csv"
echo "csv: $csv $out/upload.csv"
