#!/usr/bin/env bash
# Installs dependencies, builds, and runs the demo of what exists today: the thesis's hex
# fragment (figure 3-1) is generated, validated and compared with the shipped model library.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
bin=build/bin
out=build/demo
mkdir -p "$out"

echo "== 1. generate the hex fragment of thesis figure 3-1 (appendix B: 'hex 58 141')"
"$bin/idms-sim" generate slab --rows 5 --cols 4 --out "$out/hex_4x5_home"
echo "== 2. validate it"
"$bin/idms-sim" validate "$out/hex_4x5_home.fem" "$out/hex_4x5_home.plg"
echo "== 3. the shipped library agrees byte for byte"
for name in hex_4x5_home; do
  cmp "$out/$name.fem" "models/$name.fem" && cmp "$out/$name.plg" "models/$name.plg" && echo "models/$name: identical"
done
for name in slab_40x40 slab_40x40_tumour; do
  "$bin/idms-sim" validate "models/$name.fem" "models/$name.plg" --json
done
echo "== 4. a malformed model is rejected with FILE:LINE:COL"
sed 's/^0.5 0 0 0.002 1001 2001$/0.5 0 nan 0.002 1001 2001/' models/hex_4x5_home.fem > "$out/broken.fem"
"$bin/idms-sim" validate "$out/broken.fem" || true
