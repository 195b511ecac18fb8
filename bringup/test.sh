#!/usr/bin/env bash
# Set up, build, and run every test through CTest. Exits non-zero on any failure.
# Usage: bringup/test.sh [extra ctest arguments, e.g. -R bus -L unit]
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
case "${1:-}" in -h|--help) sed -n '2,3p' "$0" | sed 's/^# //'; exit 0 ;; esac
start=$(date +%s)
"$here/bringup/setup.sh"
built=$(date +%s)
cd "$build_dir"
status=0
ctest --output-on-failure -j"$(nproc)" "$@" || status=$?
end=$(date +%s)
echo "test.sh: set-up+build $((built - start)) s, tests $((end - built)) s, exit $status"
exit $status
