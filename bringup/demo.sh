#!/usr/bin/env bash
# Set up, build, and run the main job: the flagship experiment (paper Sec. 8.4, Figs. 12-13).
# The shipped two-object stereo session is replayed through reflex_vision -> reflex_behavior
# (pointing) -> reflex_controller as separate processes over DDS, once with collision avoidance and
# once without; the report (plots + outcome) lands in out/flagship/report.md. Then the paper's
# other experiments run on the kinematic robot (reflex_sim all), plots in out/sim/.
# Usage: bringup/demo.sh [--help] [--sim-only]
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
sim_only=0
case "${1:-}" in
  -h|--help) sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  --sim-only) sim_only=1 ;;
  "") ;;
  *) echo "demo.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
esac
"$here/bringup/setup.sh"
export REFLEX_BUILD_DIR=$build_dir
if [ "$sim_only" -eq 0 ]; then
  echo "demo.sh: flagship experiment (about 2.5 minutes: two real-time replays of a 60 s session)"
  # --view: the live 3D view of the run with avoidance at http://localhost:8765 (open it while it runs).
  /usr/bin/python3 "$here/bringup/flagship/run_flagship.py" --out "$here/out/flagship" --view "${REFLEX_VIEW_PORT:-8765}"
fi
out=$here/out/sim
echo "demo.sh: the paper's experiments on the kinematic robot (reflex_sim all)"
"$build_dir/bin/reflex_sim" all --out "$out" | grep -E "^scenario|min distance|within|e-stop"
"$build_dir/bin/reflex_sim" all --no-avoidance --out "$out/no_avoidance" > "$out/no_avoidance.txt"
echo "demo.sh: the same without avoidance (a closest distance < 0 means the segments penetrate):"
grep -E "^scenario|min distance|min virtual" "$out/no_avoidance.txt"
echo "demo.sh: done. Flagship report: out/flagship/report.md; simulation plots: out/sim/<scenario>/"
if [ "$sim_only" -eq 0 ]; then
  port=${REFLEX_VIEW_PORT:-8765}
  echo "demo.sh: the flagship run's MCAP recording (Foxglove: File -> Open local file): out/flagship/avoidance/bus.mcap"
  echo "demo.sh: the live 3D view served the run at http://localhost:$port (Foxglove: ws://localhost:$port); to watch"
  echo "         the recording there again: build/bin/reflex_view --port $port & build/bin/reflex_play --commands out/flagship/avoidance/bus.mcap"
  echo "         (--commands: the hand targets too, for the view; only with no controller running on the domain)"
fi
