#!/usr/bin/env bash
# setup_sim_chain_test: on each shipped robot, `reflex_setup` writes the robot's
# configuration and `reflex_sim all` runs the paper's seven scenarios with exactly those files. Asserted
# from every scenario's summary.txt: the closest pair never below d_r (read back from the written
# controller.yaml, else the controller's default 5 mm), no e-stop, no non-finite output, no joint faster
# than its limit. (The outcome of each scenario per robot, with the committed reference configurations,
# is asserted by controller_scenario_robots_test.)
# Usage: setup_sim_chain_test.sh SOURCE_DIR BIN_DIR
set -euo pipefail
src=$1 bin=$2
work=$(mktemp -d /tmp/reflex_setup_sim.XXXXXX)
trap 'rm -rf "$work"' EXIT
robots=$src/bringup/robots
fail() { echo "setup_sim_chain_test: FAIL: $*" >&2; exit 1; }
for robot in asimo_like small_humanoid mesh_humanoid; do
  extra=()
  [[ $robot == mesh_humanoid ]] && extra=(--srdf "$robots/mesh_humanoid.srdf"
                                          --package-path "mesh_humanoid_description=$robots/mesh_humanoid_description")
  echo "== $robot: reflex_setup"
  "$bin/reflex_setup" "$robots/$robot.urdf" "${extra[@]}" --out "$work/$robot" > "$work/$robot.setup.log" 2>&1 \
    || { cat "$work/$robot.setup.log"; fail "reflex_setup on $robot"; }
  grep -E "^(arms|hand|head|camera|rest)" "$work/$robot.setup.log" | head -8 || true
  echo "== $robot: reflex_sim all with the written files"
  "$bin/reflex_sim" all --urdf "$robots/$robot.urdf" --controller "$work/$robot/controller.yaml" \
      --collision "$work/$robot/collision.yaml" --out "$work/sim_$robot" --no-plots > "$work/$robot.sim.log" 2>&1 \
    || { tail -20 "$work/$robot.sim.log"; fail "reflex_sim all on $robot"; }
  d_r=$(sed -n -E 's/^d_r: *([0-9.eE+-]+).*/\1/p' "$work/$robot/controller.yaml" | head -1)
  d_r=${d_r:-0.005}
  n=0
  for summary in "$work/sim_$robot"/*/summary.txt; do
    n=$((n + 1))
    python3 - "$summary" "$d_r" "$robot" <<'PY' || exit 1
import re, sys
path, d_r, robot = sys.argv[1], float(sys.argv[2]), sys.argv[3]
text = open(path).read()
name = text.split()[1]
def field(label):
    m = re.search(r"^\s*" + re.escape(label) + r"\s+(.*)$", text, re.M)
    if not m:
        sys.exit(f"setup_sim_chain_test: FAIL: {robot} {name}: no '{label}' line in {path}")
    return m.group(1)
d = float(field("min distance").split()[0]) / 1000.0
problems = []
if not d >= d_r: problems.append(f"closest pair {d*1000:.2f} mm below d_r {d_r*1000:.1f} mm")
if field("e-stop fired") != "no": problems.append("e-stop fired: " + field("e-stop fired"))
if field("non-finite output") != "no": problems.append("non-finite output")
ratio = float(field("max |qdot|/v_max"))
if not ratio <= 1.0 + 1e-9: problems.append(f"a joint at {ratio} x its speed limit")
print(f"  {robot:15s} {name:22s} min {d*1000:6.1f} mm  e-stop no  |qdot|/v_max {ratio:.3f}")
if problems: sys.exit(f"setup_sim_chain_test: FAIL: {robot} {name}: " + "; ".join(problems))
PY
  done
  [[ $n -eq 7 ]] || fail "$robot: $n scenario summaries, 7 expected"
done
echo "setup_sim_chain_test: PASS (3 robots x 7 scenarios)"
