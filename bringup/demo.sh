#!/usr/bin/env bash
# Set up, build, and run the main job. Until the flagship experiment (vision -> behavior ->
# controller over DDS) exists, this runs the most complete piece that exists and says so.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
case "${1:-}" in -h|--help) sed -n '2,3p' "$0" | sed 's/^# //'; exit 0 ;; esac
"$here/bringup/setup.sh"
echo "demo.sh: the flagship experiment does not exist yet; nothing else to run"
