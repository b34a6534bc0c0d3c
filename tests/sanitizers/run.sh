#!/usr/bin/env bash
# Runs a sanitized test executable so that any sanitizer report fails the test: the reports of the
# test and of every process it starts (idms-server, idms-agent, which inherit the environment) go
# to files in REPORT_DIR (log_path=DIR/KIND.PID), which are printed and counted afterwards, so a
# report from a child the test SIGKILLs or never waits for still fails it.
# Usage: run.sh tsan|asan REPORT_DIR COMMAND [ARGS...]
set -uo pipefail
kind=$1 dir=$2
shift 2
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$dir"
mkdir -p "$dir"
# The test's temporary directories (servers' data, logs) under the report directory, kept for a look.
export TEST_TMPDIR=$dir/tmp
mkdir -p "$TEST_TMPDIR"

case $kind in
  tsan)
    # halt_on_error: the first race stops the process (a server that dies fails its test at once);
    # second_deadlock_stack: both stacks of a lock-order inversion.
    export TSAN_OPTIONS="halt_on_error=1 exitcode=66 second_deadlock_stack=1 history_size=4 log_path=$dir/tsan suppressions=$here/tsan.supp"
    ;;
  asan)
    # detect_leaks: LeakSanitizer at every exit (the servers are stopped with SIGTERM in this build,
    # see tests/server/server_process.cc, so that their leaks are checked too).
    export ASAN_OPTIONS="detect_leaks=1 halt_on_error=1 detect_stack_use_after_return=1 strict_init_order=1 check_initialization_order=1 log_path=$dir/asan"
    export LSAN_OPTIONS="suppressions=$here/lsan.supp print_suppressions=0"
    export UBSAN_OPTIONS="halt_on_error=1 print_stacktrace=1 log_path=$dir/ubsan"
    ;;
  *)
    echo "run.sh: unknown kind '$kind' (tsan or asan)" >&2
    exit 2
    ;;
esac

"$@"
status=$?

# Every report file, whoever wrote it.
reports=()
for f in "$dir"/tsan.* "$dir"/asan.* "$dir"/ubsan.*; do
  [ -s "$f" ] && reports+=("$f")
done
for f in "${reports[@]}"; do
  echo "==== $kind report: $f"
  cat "$f"
done
if [ ${#reports[@]} -gt 0 ]; then
  echo "run.sh: ${#reports[@]} $kind report file(s) in $dir (test exit status $status)"
  exit 1
fi
exit $status
