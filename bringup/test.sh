#!/usr/bin/env bash
# Set up, build, and run every test through CTest, then the hygiene phases. Exits non-zero on any
# failure (a test, a sanitizer report, a fuzz finding).
# Usage: bringup/test.sh [--no-hygiene | --hygiene-only] [extra ctest arguments, e.g. -R bus -L unit]
#   1. bringup/setup.sh: packages + Release build in build/; ctest there (with the extra arguments).
#   2. Hygiene, in ONE clang build folder (build-fuzz/, -fsanitize=fuzzer-no-link,
#      address,undefined): the non-DDS unit tests below under ASan + UBSan (bringup/sanitize.sh
#      --clang-fuzz --tests ...), then every libFuzzer target for REFLEX_FUZZ_SECONDS s each
#      (bringup/fuzz.sh). The DDS tests under sanitizers (sanitize.sh --dds) and longer fuzzing
#      run by hand only; see tests/fuzz/README.md.
#   --no-hygiene or REFLEX_HYGIENE=0  skip step 2;  --hygiene-only  packages + step 2 only
#   REFLEX_FUZZ_SECONDS (default 10)  fuzzing time per target
#   REFLEX_FUZZ_SEED (default 1)      libFuzzer seed: CI replays the same inputs run after run, so a
#                                     red run is a change's doing; new ground by hand (fuzz.sh, no --seed)
#   REFLEX_FUZZ_BUILD_DIR             the clang folder (default <repo>/build-fuzz)
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
fuzz_dir=${REFLEX_FUZZ_BUILD_DIR:-$here/build-fuzz}
fuzz_seconds=${REFLEX_FUZZ_SECONDS:-10}
fuzz_seed=${REFLEX_FUZZ_SEED:-1}
hygiene=${REFLEX_HYGIENE:-1}
release=1
case "${1:-}" in
  -h|--help) sed -n '2,/^set -e/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  --no-hygiene) hygiene=0; shift ;;
  --hygiene-only) hygiene=1; release=0; shift ;;
esac
[[ "$fuzz_seed" =~ ^[1-9][0-9]*$ ]] || { echo "test.sh: REFLEX_FUZZ_SEED '$fuzz_seed' is not a positive integer" >&2; exit 2; }
[[ "$fuzz_seconds" =~ ^[1-9][0-9]*$ ]] || { echo "test.sh: REFLEX_FUZZ_SECONDS '$fuzz_seconds' is not a positive integer" >&2; exit 2; }

# The sanitized subset (ctest -R; sanitize.sh's labels still apply): the unit tests of the file
# parsers (URDF, controller / behavior YAML, recordings, camera calibration), every behavior
# module, geometry, self-distances and kinematics (randomized cross-checks against FCL and KDL),
# and one full controller cycle (controller_alloc_test). Left to `bringup/sanitize.sh` by hand, for
# time: controller_test (~3 min under ASan), the vision session, replay and process tests, and every
# DDS test (--dds).
hygiene_tests='^(control_(geometry|distance|distance_alloc|kinematics|urdf_loader)_test|controller_(config|alloc)_test|modules_(pointing|host|config|scripted|body_schema)_test|record_file_test|vision_calibration_test)$'

start=$(date +%s)
status=0
summary=()
if [[ $release -eq 1 ]]; then
  "$here/bringup/setup.sh"
  built=$(date +%s)
  (cd "$build_dir" && ctest --output-on-failure -j"$(nproc)" "$@") || status=$?
  # No test may leave the machine's null and full devices replaced (tests that need a full device
  # make their own; a tool that replaced one would break every later run on this machine).
  for node in /dev/null /dev/full; do
    if [ ! -c "$node" ]; then
      echo "test.sh: $node is no longer a character device after the tests" >&2
      status=1
    fi
  done
  tested=$(date +%s)
  summary+=("set-up+build $((built - start)) s" "tests $((tested - built)) s (exit $status)")
else
  "$here/bringup/setup.sh" --no-build
fi

if [[ "$hygiene" != 0 ]]; then
  t0=$(date +%s)
  san=0
  "$here/bringup/sanitize.sh" --clang-fuzz --build-dir "$fuzz_dir" --tests "$hygiene_tests" --test-jobs "$(nproc)" ||
    san=$?
  t1=$(date +%s)
  fz=0
  "$here/bringup/fuzz.sh" --build-dir "$fuzz_dir" --time "$fuzz_seconds" --seed "$fuzz_seed" || fz=$?
  t2=$(date +%s)
  summary+=("sanitized build+tests $((t1 - t0)) s (exit $san)" "fuzz build+${fuzz_seconds} s per target $((t2 - t1)) s (exit $fz)")
  if [[ $san -ne 0 || $fz -ne 0 ]] && [[ $status -eq 0 ]]; then status=1; fi
else
  summary+=("hygiene skipped")
fi
end=$(date +%s)
summary+=("total $((end - start)) s")
line=""
for part in "${summary[@]}"; do line+="${line:+, }$part"; done
echo "test.sh: $line, exit $status"
exit $status
