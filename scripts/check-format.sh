#!/usr/bin/env bash
# The C++ the project owns is clang-format clean (.clang-format: Google style, 120 columns).
# Exit 0 when it is; else clang-format's diagnostics name each file, line and column, exit 1.
# Fix with: git ls-files '*.cc' '*.h' | grep -v /gen/ | xargs clang-format -i
set -euo pipefail
cd "$(dirname "$0")/.."
command -v clang-format >/dev/null || { echo "check-format: clang-format not installed (scripts/install-deps.sh)"; exit 2; }
mapfile -t files < <(git ls-files --cached --others --exclude-standard '*.cc' '*.h' | grep -v -e node_modules -e '/gen/' |
  while read -r f; do [ -f "$f" ] && echo "$f"; done)
[ "${#files[@]}" -gt 0 ] || { echo "check-format: no C++ files found (not a git checkout?)"; exit 2; }
clang-format --dry-run --Werror "${files[@]}"
echo "check-format: ${#files[@]} files clean"
