#!/usr/bin/env bash
# Regenerates docs/figures/: the thesis's chapter 6 interactions on the hex fragment (figures
# 6-2, 6-3, 6-5, 6-6, 6-8) with idms-sim run on the thesis's own step (--preset thesis: explicit
# Euler, haptic window 2.25 = 1.5 r, section 6.2). Needs a build (scripts/build.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
sim=build/bin/idms-sim
out=docs/figures
mkdir -p "$out"
for script in palpate stroke-slow stroke-fast pluck; do
  extra=()
  [ "$script" = palpate ] && extra=(--fit-plot "$out/palpate-fit.png")
  "$sim" run --preset thesis --model models/hex_4x5_home --script "$script" --csv "$out/$script.csv" --plot "$out/$script.png" \
    "${extra[@]}" --json | tee "$out/$script.json"
done
# The strokes' crossings up close (t = 2.9 to 3.5 s), where the three fast crossings take 0.3 s.
for script in stroke-slow stroke-fast; do
  "$sim" run --preset thesis --model models/hex_4x5_home --script "$script" --csv "$out/$script.csv" \
    --plot "$out/$script-crossing.png" --plot-window 2.9,3.5 >/dev/null
done
