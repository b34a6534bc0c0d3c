#!/usr/bin/env bash
# Installs dependencies, builds, and runs the demo of what exists today: the thesis's hex
# fragment (figure 3-1) is generated, validated and compared with the shipped model library,
# then palpated, stroked and plucked offline (thesis chapter 6) with plots in build/demo/, and the
# device agent runs its 1 kHz loop on a scripted palpation for two seconds.
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
echo "== 5. the thesis's interactions offline (figures 6-2, 6-3, 6-5, 6-6, 6-8)"
for script in palpate stroke-slow stroke-fast pluck; do
  "$bin/idms-sim" run --model models/hex_4x5_home --script "$script" --csv "$out/$script.csv" --plot "$out/$script.png"
done
"$bin/idms-sim" run --model models/hex_4x5_home --script palpate --fit-plot "$out/palpate-fit.png" --json
echo "== 6. the haptic window's stability (thesis 4.2) at the nominal parameters"
"$bin/idms-sim" stability --k 15 --b 0.45 --m 0.002 --dt 0.001
echo "== 7. the device agent's 1 kHz DSM loop, offline (--server none), 2 s of scripted palpation"
"$bin/idms-agent" --server none --model-file models/hex_4x5_home --device scripted:palpate \
  --scene models/palpate.scene --duration 2 --summary-json "$out/agent.json"
echo "plots: $out/*.png; the agent's figures: $out/agent.json"
