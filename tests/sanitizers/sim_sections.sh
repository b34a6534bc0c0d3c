#!/usr/bin/env bash
# Full mode's pass on several threads (StepOptions::threads) under a sanitizer: a renumbered slab
# pressed and plucked with --threads 3 (sections, cross elements, the worker pool's hand-offs; a
# scripted tool on top), and compared with one thread: the same forces, tick by tick; then the
# global pass on its own thread beside a local run (issue 33).
# Usage: sim_sections.sh IDMS_SIM (run by run.sh, which sets TEST_TMPDIR)
set -euo pipefail
sim=$1
dir=$(mktemp -d -p "${TEST_TMPDIR:-/tmp}" sections.XXXXXX)
"$sim" generate slab --rows 24 --cols 24 --out "$dir/slab" > /dev/null
"$sim" reorder --model "$dir/slab" --out "$dir/ordered" > /dev/null
for script in palpate pluck; do
  for threads in 1 3; do
    "$sim" run --model "$dir/ordered" --full --threads $threads --script $script --ticks 2800 \
      --csv "$dir/$script.$threads.csv" > /dev/null
    # Every column but the time it took (compute_us, the 10th).
    cut -d, -f1-9 "$dir/$script.$threads.csv" > "$dir/$script.$threads.cut"
  done
  cmp "$dir/$script.1.cut" "$dir/$script.3.cut"
done
# The global pass on its own thread beside the local loop (the hand-offs, a clean stop).
"$sim" run --model "$dir/slab" --global-rate 100 --global-thread --script pluck --ticks 1500 --json > "$dir/global.json"
grep -q '"threaded": *true' "$dir/global.json"
echo "sim_sections: 3 threads gave one thread's results; the global thread ran"
