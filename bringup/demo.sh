#!/usr/bin/env bash
# Set up, build, and run the main job.
# Until the flagship experiment (recorded session -> vision -> behavior -> controller over DDS) lands,
# the main job is the most complete piece that exists: the paper's experiments (Sec. 8) on the
# kinematic robot with reflex_sim, each with and without collision avoidance, plots in out/sim/.
# Usage: bringup/demo.sh [--help]
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
case "${1:-}" in -h|--help) sed -n '2,6p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;; esac
"$here/bringup/setup.sh"
out=$here/out/sim
echo "demo.sh: the flagship experiment is not built yet; running the paper's experiments in simulation"
echo "demo.sh: the robot's collision model (reflex_inspect, closest pairs at rest):"
"$build_dir/bin/reflex_inspect" "$here/bringup/robots/asimo_like.urdf" | grep -v '^#' | sort -t, -k3 -g | head -6
"$build_dir/bin/reflex_sim" all --out "$out"
"$build_dir/bin/reflex_sim" all --no-avoidance --out "$out/no_avoidance" > "$out/no_avoidance.txt"
echo "demo.sh: without avoidance (closest distance < 0 means the segments penetrate):"
grep -E "^scenario|min distance|min virtual" "$out/no_avoidance.txt"
echo "demo.sh: done. Plots and time series: $out/<scenario>/ (distance_f.png, hands.png, joints.png, postures.png)"
