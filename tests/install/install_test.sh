#!/usr/bin/env bash
# install_test: Reflex as a library for outside projects.
#  1. `cmake --install` of the build tree into a fresh prefix;
#  2. a tiny outside project (tests/install/outside_project) finds it with find_package(reflex), links
#     reflex::control and reflex::vision, and prints what the in-tree tools answer independently
#     (reflex_inspect's segment/pair count; the baseline computed here from the calibration's numbers);
#     its second program links reflex::vision_node and runs the vision node offline on the flagship
#     session: its CSV must equal the in-tree reflex_vision --dump byte for byte;
#  3. docs/library.md: its CMakeLists.txt, main.cpp and build commands, extracted from the page, built
#     and run against the prefix; its answer checked against reflex_inspect's distances;
#  4. the out-of-tree module project modules/examples/wave_module builds as a plugin against the installed
#     tree and runs in the INSTALLED stock reflex_behavior on the bus: `reflex_bus list` sees its module
#     and `reflex_bus hz` counts its hand targets; without the plugin the configuration is refused, and a
#     library that is not a plugin is refused by name;
#  5. find_package(reflex COMPONENTS control) in a project that forbids finding Fast DDS, OpenCV and
#     OpenSSL; an unknown component is refused by name;
#  6. the prefix copied elsewhere and the checkout (and build tree) hidden by a mount namespace: the
#     moved tree alone runs `reflex_sim all`, `reflex_setup` on a shipped mesh robot, and the plugin
#     module in reflex_behavior, each finding its data in the moved PREFIX/share/reflex.
# Usage: install_test.sh SOURCE_DIR BUILD_DIR DOMAIN
set -euo pipefail
src=$1 build=$2 domain=$3
work=$(mktemp -d /tmp/reflex_install_test.XXXXXX)
trap '[[ -n ${KEEP_WORK:-} ]] || rm -rf "$work"' EXIT
prefix=$work/prefix
fail() { echo "install_test: FAIL: $*" >&2; exit 1; }
step() { echo "install_test: [$(date +%T)] $*"; }

step "cmake --install into $prefix"
cmake --install "$build" --prefix "$prefix" > "$work/install.log" || { tail -20 "$work/install.log"; fail "cmake --install"; }
for f in lib/cmake/reflex/reflexConfig.cmake lib/cmake/reflex/reflex-control-targets.cmake include/reflex/control/controller.hpp \
         include/reflex/msg/control.h include/reflex/modules/plugin.hpp include/reflex/vision_node/vision_node.hpp bin/reflex_controller bin/reflex_behavior \
         bin/reflex_bus bin/reflex_plot_sim.py share/reflex/robots/asimo_like.urdf share/reflex/dds/reflex_profiles.xml \
         share/reflex/view/web/index.html share/reflex/view/three/three.module.js share/reflex/sessions/flagship/session.yaml; do
  [[ -e $prefix/$f ]] || fail "not installed: $f"
done

step "outside project: find_package(reflex), reflex::control + reflex::vision (+ reflex::vision_node)"
cmake -S "$src/tests/install/outside_project" -B "$work/outside" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_BUILD_TYPE=Release > "$work/outside.log" 2>&1 || { cat "$work/outside.log"; fail "configure outside project"; }
cmake --build "$work/outside" -j2 >> "$work/outside.log" 2>&1 || { tail -30 "$work/outside.log"; fail "build outside project"; }
urdf=$src/bringup/robots/asimo_like.urdf
session=$src/bringup/sessions/flagship
out=$("$work/outside/outside_check" "$urdf" "$session/left.yaml" "$session/right.yaml")
echo "$out"
"$build/bin/reflex_inspect" "$urdf" > "$work/inspect.out"
want=$(sed -n -E '1s/^# (robot [^:]+: [0-9]+ segments, [0-9]+ checked pairs).*/\1/p' "$work/inspect.out")
[[ $(echo "$out" | head -1) == "$want" ]] || fail "outside_check says '$(echo "$out" | head -1)', reflex_inspect '$want'"
baseline=$(python3 -c "
import re,sys
d=re.search(r'projection_matrix:.*?data:\s*\[([^\]]*)\]', open('$session/right.yaml').read(), re.S).group(1)
p=[float(x) for x in d.split(',')]
print('%.6f' % (-p[3]/p[0]))")
[[ $(echo "$out" | sed -n 2p) == "baseline $baseline" ]] || fail "baseline: '$(echo "$out" | sed -n 2p)' != $baseline"

grep -l '/usr/lib/.*\.so' "$prefix"/lib/cmake/reflex/*.cmake && fail "an exported target names a library by its absolute path (above)"

step "find_package(reflex COMPONENTS control): reflex::control alone, Fast DDS / OpenCV / OpenSSL never looked for"
cmake -S "$src/tests/install/control_only" -B "$work/control_only" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_BUILD_TYPE=Release > "$work/control_only.log" 2>&1 || { cat "$work/control_only.log"; fail "configure control_only"; }
cmake --build "$work/control_only" -j2 >> "$work/control_only.log" 2>&1 || { tail -30 "$work/control_only.log"; fail "build control_only"; }
got=$("$work/control_only/control_only" "$urdf")
[[ $got == "$want" ]] || fail "control_only says '$got', reflex_inspect '$want'"
echo "install_test: COMPONENTS control: $got"
mkdir -p "$work/unknown"
printf 'cmake_minimum_required(VERSION 3.22)\nproject(unknown NONE)\nfind_package(reflex 0.1 REQUIRED COMPONENTS contrl)\n' \
  > "$work/unknown/CMakeLists.txt"
bad=$(cmake -S "$work/unknown" -B "$work/unknown/build" -DCMAKE_PREFIX_PATH="$prefix" 2>&1) \
  && fail "find_package(reflex COMPONENTS contrl) was accepted"
grep -q "unknown component 'contrl'" <<<"$bad" || fail "an unknown component is refused without naming it: $bad"

step "outside project: reflex::vision_node offline on the flagship session vs the in-tree reflex_vision --dump"
"$work/outside/outside_vision_node" "$session" "$work/node.csv" || fail "outside_vision_node"
"$build/bin/reflex_vision" --session "$session" --dump "$work/exe.csv" --duration 2 --quiet 2> "$work/exe.err" \
  || fail "reflex_vision --dump: $(cat "$work/exe.err")"
rows=$(($(wc -l < "$work/exe.csv") - 1))
[[ $rows -gt 10 ]] || fail "reflex_vision --dump wrote $rows detections (> 10 expected)"
cmp -s "$work/node.csv" "$work/exe.csv" || fail "the installed reflex::vision_node's CSV differs from reflex_vision --dump: $(diff "$work/node.csv" "$work/exe.csv" | head -5)"
echo "install_test: reflex::vision_node: $rows detections, identical to reflex_vision --dump"

step "docs/library.md: its CMakeLists.txt and main.cpp, extracted from the page, built and run against the prefix"
mkdir -p "$work/library"
python3 - "$src/docs/library.md" "$work/library" <<'PY' || fail "docs/library.md: cannot extract its blocks"
import re, sys
page = open(sys.argv[1]).read()
blocks = re.findall(r"^```(\w+)\n(.*?)^```", page, re.S | re.M)
files = {"cmake": ("# CMakeLists.txt", "CMakeLists.txt"), "cpp": ("// main.cpp", "main.cpp")}
written = 0
for lang, body in blocks:
    if lang in files and body.startswith(files[lang][0]):
        open(sys.argv[2] + "/" + files[lang][1], "w").write(body)
        written += 1
    if lang == "sh":
        open(sys.argv[2] + "/commands.sh", "w").write(body)
        written += 1
sys.exit(0 if written == 3 else 1)
PY
(cd "$work/library" && PREFIX=$prefix ROBOTS=$src/bringup/robots bash -e commands.sh) > "$work/library.out" 2>&1 \
  || { tail -30 "$work/library.out"; fail "docs/library.md's commands"; }
got=$(grep '^closest between the arms:' "$work/library.out") || fail "docs/library.md's program printed: $(tail -5 "$work/library.out")"
echo "$got"
# The independent answer: reflex_inspect's distances at the zero posture, the least over the pairs of
# a left-arm and a right-arm segment (the default controller configuration's arms, asimo_like's, move
# these segments).
want=$("$build/bin/reflex_inspect" "$urdf" | python3 -c "
import sys
arm = lambda s: s.split('_', 1)[0] if s.split('_', 1)[-1] in ('shoulder', 'upper_arm', 'forearm', 'hand') else None
best = None
for line in sys.stdin:
    f = line.strip().split(',')
    if line.startswith('#') or len(f) < 3 or f[0] == 'segment_a': continue
    if arm(f[0]) and arm(f[1]) and arm(f[0]) != arm(f[1]) and (best is None or float(f[2]) < float(best[2])): best = f
print('closest between the arms: %s %s %.6f m' % (best[0], best[1], float(best[2])))")
[[ $got == "$want" ]] || fail "docs/library.md's program says '$got', reflex_inspect '$want'"
grep -qF "It prints \`$got\`" "$src/docs/library.md" \
  || fail "docs/library.md states another output than its program prints ('$got')"

step "out-of-tree module plugin: modules/examples/wave_module"
cmake -S "$src/modules/examples/wave_module" -B "$work/wave" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_BUILD_TYPE=Release > "$work/wave.log" 2>&1 || { cat "$work/wave.log"; fail "configure wave_module"; }
cmake --build "$work/wave" -j2 >> "$work/wave.log" 2>&1 || { tail -30 "$work/wave.log"; fail "build wave_module"; }
plugin=$work/wave/libreflex_wave_module.so
exported=$(nm -D --defined-only "$plugin" | awk '{print $3}' | grep -c . || true)
nm -D --defined-only "$plugin" | grep -q ' reflex_register_modules$' || fail "plugin lacks reflex_register_modules"
[[ $exported -le 4 ]] || fail "the plugin exports $exported symbols (visibility hidden expected: only the entry points)"
behavior=$prefix/bin/reflex_behavior
"$behavior" --list-modules --plugin "$plugin" | grep -q '^wave ' || fail "--list-modules --plugin does not list 'wave'"
config=$src/modules/examples/wave_module/wave.yaml

# Refusals: exit 2 and the exact message. refused WHAT EXPECTED_TEXT ARGS...
refused() {
  local what=$1 want=$2; shift 2
  local msg rc=0
  msg=$("$behavior" --config "$config" "$@" 2>&1) || rc=$?
  [[ $rc -eq 2 ]] && grep -qF -- "$want" <<<"$msg" || fail "$what: exit $rc (2 expected), got: $msg"
}
refused "without the plugin" "modules[0].type: unknown module type (value 'wave', expected one of grasped_bar, occlusion, pointing, scripted, walking)" \
  --domain "$domain" --duration 1
notplugin=$(ls /usr/lib/x86_64-linux-gnu/libz.so.1 /lib/x86_64-linux-gnu/libz.so.1 2>/dev/null | head -1)
refused "a library that is no plugin" "module plugin '$notplugin': not a Reflex module plugin" --plugin "$notplugin"
refused "a missing plugin" "module plugin '$work/missing.so': no such file" --plugin "$work/missing.so"
refused "the plugin twice" "module type 'wave' is already registered" --plugin "$plugin" --plugin "$plugin"
# Two hand-made libraries with the entry points: another API tag, and a plugin that registers nothing.
for kind in old_api empty; do
  tag='"reflex-module-api/1"'; [[ $kind == old_api ]] && tag='"reflex-module-api/0"'
  cat > "$work/$kind.cpp" <<CPP
namespace reflex::modules { class ModuleRegistry; }
extern "C" const char* reflex_module_api_tag() { return $tag; }
extern "C" void reflex_register_modules(reflex::modules::ModuleRegistry&) {}
CPP
  g++ -shared -fPIC -o "$work/lib$kind.so" "$work/$kind.cpp" || fail "cannot build lib$kind.so"
done
refused "a plugin of another API" \
  "module plugin '$work/libold_api.so': built for 'reflex-module-api/0', this reflex_behavior is 'reflex-module-api/1'" \
  --plugin "$work/libold_api.so"
refused "a plugin registering nothing" "module plugin '$work/libempty.so': registers no module type" \
  --plugin "$work/libempty.so"

step "the plugin's module in the installed reflex_behavior, on the bus (domain $domain)"
"$behavior" --config "$config" --plugin "$plugin" --domain "$domain" --duration 120 > "$work/behavior.out" 2> "$work/behavior.err" &
bpid=$!
# Discovery on a loaded machine can take seconds: ask until the module is seen (at most ~40 s).
seen=0
for _ in $(seq 20); do
  "$prefix/bin/reflex_bus" list --domain "$domain" --window 2 > "$work/list.out" 2>&1 || true
  if grep -q "modules: wave" "$work/list.out"; then seen=1; break; fi
  kill -0 $bpid 2>/dev/null || break
done
"$prefix/bin/reflex_bus" hz reflex/hand_targets --domain "$domain" --window 3 > "$work/hz.out" 2>&1 || true
kill -TERM $bpid 2>/dev/null || true
rc=0; wait $bpid || rc=$?
cat "$work/list.out" "$work/hz.out"
[[ $rc -eq 0 ]] || fail "reflex_behavior with the plugin exited $rc after SIGTERM (0 expected: main's StopOnSignal): $(cat "$work/behavior.err")"
grep -q "plugin $plugin: module types wave" "$work/behavior.err" || fail "no plugin line on stderr: $(cat "$work/behavior.err")"
[[ $seen -eq 1 ]] || fail "reflex_bus list never showed the wave module: $(cat "$work/list.out")"
grep -q "hand_targets=[1-9]" "$work/behavior.out" || fail "the exit line counts no hand target: $(cat "$work/behavior.out")"
rate=$(awk '/reflex\/hand_targets/ {print $3; exit}' "$work/hz.out")
python3 -c "import sys; r=float('${rate:-0}'); sys.exit(0 if r >= 5 else 1)" \
  || fail "hand targets from the plugin at ${rate:-0}/s (>= 5 expected: it steps every 50 ms)"

step "the prefix moved elsewhere and the checkout out of reach (a mount namespace hides $src): the installed tree alone"
moved=$work/moved
cp -a "$prefix" "$moved"
# The wave configuration without its checkout-relative robot: the installed reflex_behavior's default robot.
python3 - "$config" "$work/wave_alone.yaml" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
open(sys.argv[2], "w").write(re.sub(r"^robot:\n(  .*\n)+\n?", "", text, flags=re.M))
PY
grep -q '^robot:' "$work/wave_alone.yaml" && fail "could not drop robot: from $config"
hide=("$src")
[[ $build == "$src"/* ]] || hide+=("$build")
sim_count=$("$build/bin/reflex_sim" --list | grep -cE '^[a-z_0-9]+ ' || true)
unshare --mount --propagation private bash -s -- "$moved" "$work" "$domain" "$plugin" "${hide[@]}" > "$work/moved.out" 2>&1 <<'SH' \
  || { cat "$work/moved.out"; fail "the moved prefix (above)"; }
set -euo pipefail
moved=$1 work=$2 domain=$3 plugin=$4; shift 4
for dir in "$@"; do mount -t tmpfs tmpfs "$dir"; done
for dir in "$@"; do [[ -z $(ls -A "$dir") ]] || { echo "could not hide $dir"; exit 1; }; done
echo "hidden: $*"
cd "$work"
"$moved/bin/reflex_sim" all --out "$work/sim_moved" > "$work/sim_moved.log" 2>&1 || { tail -20 "$work/sim_moved.log"; exit 1; }
echo "reflex_sim all: $(ls "$work/sim_moved" | wc -l) scenario folders, default robot $("$moved/bin/reflex_sim" --help | grep -o '/[^ ]*asimo_like.urdf')"
robots=$moved/share/reflex/robots
"$moved/bin/reflex_setup" "$robots/mesh_humanoid.urdf" --srdf "$robots/mesh_humanoid.srdf" \
  --package-path "mesh_humanoid_description=$robots/mesh_humanoid_description" --out "$work/setup_moved" \
  > "$work/setup_moved.log" 2>&1 || { tail -20 "$work/setup_moved.log"; exit 1; }
echo "reflex_setup: $(ls "$work/setup_moved" | tr '\n' ' ')"
"$moved/bin/reflex_behavior" --config "$work/wave_alone.yaml" --plugin "$plugin" --domain "$domain" --duration 3 \
  > "$work/behavior_moved.out" 2> "$work/behavior_moved.err" || { cat "$work/behavior_moved.err"; exit 1; }
grep -q "hand_targets=[1-9]" "$work/behavior_moved.out" || { echo "no hand target: $(cat "$work/behavior_moved.out")"; exit 1; }
echo "reflex_behavior with the plugin: $(grep -o 'hand_targets=[0-9]*' "$work/behavior_moved.out")"
SH
cat "$work/moved.out"
got_count=$(ls "$work/sim_moved" | wc -l)
[[ $sim_count -gt 0 && $got_count -eq $sim_count ]] || fail "reflex_sim all from the moved prefix wrote $got_count scenario folders, reflex_sim --list names $sim_count"
grep -q "default robot $moved/share/reflex/robots/asimo_like.urdf" "$work/moved.out" \
  || fail "the moved reflex_sim's default robot is not the moved prefix's: $(grep 'default robot' "$work/moved.out")"
for f in controller.yaml collision.yaml behavior.yaml; do
  [[ -s $work/setup_moved/$f ]] || fail "reflex_setup from the moved prefix wrote no $f"
done
step "PASS (hand targets ${rate}/s)"
