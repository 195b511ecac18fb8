#!/usr/bin/env bash
# sanitize.sh — the Reflex test suite under AddressSanitizer + UndefinedBehaviorSanitizer.
#
# Configures a separate build dir with -DREFLEX_SANITIZE=ON (top CMakeLists: -fsanitize=address,
# undefined), builds only the test programs (and the executables they start) selected by the
# labels, runs them with ctest, and exits non-zero if a test fails or if any sanitizer report
# appears in the output (also one from a child process whose exit code a test ignored).
#
# Default selection (CI): labels unit|control|vision|modules|bad_input, excluding the long DDS
# system tests, experiments and the soak (labels system|integration|flagship|netns|launch|experiment|
# security|soak).
# Pass --labels '.' --exclude '^$' for everything.
# CI (bringup/test.sh) runs a named subset instead, in the clang folder of the fuzz targets:
# --clang-fuzz --tests REGEX (one extra build for both, see tests/fuzz/README.md).
set -euo pipefail

usage() {
  cat <<'EOF'
usage: sanitize.sh [--build-dir DIR] [--labels REGEX] [--exclude REGEX] [--tests REGEX] [--dds]
                   [--clang-fuzz] [--jobs N] [--test-jobs N] [--no-build]

Runs the Reflex tests under AddressSanitizer + UndefinedBehaviorSanitizer.

  --build-dir DIR   build folder (default: <repo>/build-sanitize)
  --labels REGEX    ctest -L: labels to run (default: 'unit|control|vision|modules|bad_input')
  --exclude REGEX   ctest -LE: labels to skip
                    (default: 'system|integration|flagship|netns|launch|experiment|security|soak')
  --tests REGEX     ctest -R: only the tests whose name matches (within the labels); only their
                    own executables are built (and what they declare with add_dependencies), not
                    every reflex_* executable
  --clang-fuzz      configure the folder as bringup/fuzz.sh does (clang, -fsanitize=fuzzer-no-link,
                    address,undefined, REFLEX_FUZZ=ON; default folder <repo>/build-fuzz) instead of
                    gcc + REFLEX_SANITIZE, so the same build also serves fuzz.sh (CI)
  --dds             the DDS tests instead: labels 'bus|bad_input|faults|security|system', excluding
                    'netns|launch|flagship'; ASan's new-delete-type-mismatch check is off for them
                    (Debian's libfastrtps 2.9.1 reports one inside RTPSReader::~RTPSReader on every
                    reader deletion — third party) and bringup/sanitize_dds.lsan.supp is loaded
                    (Fast DDS Security leaks on a refused participant)
  --jobs N          build jobs (default 2)
  --test-jobs N     tests run at once (ctest -j; default 1)
  --no-build        run the tests of an existing build only
  -h, --help        this help
Exit status: 0 clean; 1 a test failed or a sanitizer reported; 2 bad arguments or build failure.
EOF
}

die() { echo "sanitize.sh: error: $*" >&2; exit 2; }

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$repo/build-sanitize"
labels='unit|control|vision|modules|bad_input'
exclude='system|integration|flagship|netns|launch|experiment|security|soak'
jobs=2
test_jobs=1
do_build=1
dds=0
clang_fuzz=0
names=''
while [[ $# -gt 0 ]]; do
  case "$1" in
    -h|--help) usage; exit 0 ;;
    --build-dir) [[ $# -ge 2 ]] || die "--build-dir needs a folder"; build="$2"; shift 2 ;;
    --labels) [[ $# -ge 2 ]] || die "--labels needs a regex"; labels="$2"; shift 2 ;;
    --exclude) [[ $# -ge 2 ]] || die "--exclude needs a regex"; exclude="$2"; shift 2 ;;
    --jobs)
      [[ $# -ge 2 && "$2" =~ ^[1-9][0-9]*$ ]] || die "--jobs '${2:-}' is not a positive integer"
      jobs="$2"; shift 2 ;;
    --tests) [[ $# -ge 2 ]] || die "--tests needs a regex"; names="$2"; shift 2 ;;
    --clang-fuzz) clang_fuzz=1; shift ;;
    --test-jobs)
      [[ $# -ge 2 && "$2" =~ ^[1-9][0-9]*$ ]] || die "--test-jobs '${2:-}' is not a positive integer"
      test_jobs="$2"; shift 2 ;;
    --no-build) do_build=0; shift ;;
    --dds) dds=1; labels='bus|bad_input|faults|security|system'; exclude='netns|launch|flagship'; shift ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
done

if [[ $clang_fuzz -eq 1 && "$build" == "$repo/build-sanitize" ]]; then build="$repo/build-fuzz"; fi
# ctest's selection: labels, minus excluded labels, and the name regex if given.
select=(-L "$labels" -LE "$exclude")
if [[ -n "$names" ]]; then select+=(-R "$names"); fi

start=$(date +%s)
if [[ $do_build -eq 1 ]]; then
  mkdir -p "$build" || die "cannot create the build folder '$build'"
  if [[ $clang_fuzz -eq 1 ]]; then
    "$repo/bringup/fuzz.sh" --configure-only --build-dir "$build" > "$build/sanitize.configure.log" 2>&1 ||
      { cat "$build/sanitize.configure.log" >&2; die "configure of '$build' (fuzz.sh --configure-only) failed"; }
  else
    cmake -S "$repo" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DREFLEX_SANITIZE=ON \
      -DREFLEX_BUILD_BENCHMARKS=OFF > "$build/sanitize.configure.log" 2>&1 ||
      { cat "$build/sanitize.configure.log" >&2; die "configure of '$build' failed"; }
  fi
fi
[[ -f "$build/CTestTestfile.cmake" ]] || die "'$build' is not a configured build folder"

# The selected tests; each test's name is its executable's target (reflex_add_test).
mapfile -t tests < <(cd "$build" && ctest -N "${select[@]}" | sed -n 's/^ *Test *#[0-9]*: *//p')
[[ ${#tests[@]} -gt 0 ]] || die "no test matches labels '$labels' minus '$exclude'${names:+ and names '$names'}"
echo "sanitize.sh: ${#tests[@]} tests: ${tests[*]}"

# The executables of the selected tests (one program may serve several tests), read from the
# generated CTestTestfile.cmake files (ctest hides commands not built yet), plus every reflex_*
# executable (tests start them as child processes).
list_targets() {
  python3 - "$build" "${tests[@]}" <<'PY'
import os, re, sys
build, wanted = sys.argv[1], set(sys.argv[2:])
exes = set()
for root, _, files in os.walk(os.path.join(build, "tests")):
    if "CTestTestfile.cmake" in files:
        text = open(os.path.join(root, "CTestTestfile.cmake")).read()
        for name, exe in re.findall(r'add_test\(\[=\[(.*?)\]=\] "([^"]+)"', text):
            if name in wanted:
                exes.add(os.path.basename(exe))
print("\n".join(sorted(exes)))
PY
  # With --tests, the tests' own executables only (their add_dependencies come along).
  [[ -z "$names" ]] || return 0
  # reflex_* executables, and the fuzz replays / seed writer that script-driven tests run.
  build_targets | grep -E '^(reflex|fuzz)_[A-Za-z0-9_]*$' || true
}

# Every build target's name, from `cmake --build --target help`: "... name" with Makefiles,
# "name: phony" with Ninja (fuzz.sh configures new folders with Ninja).
build_targets() {
  # (captured first: grep -q on a pipe would SIGPIPE cmake and fail under pipefail)
  local help
  help=$(cmake --build "$build" --target help 2>/dev/null || true)
  sed -n -e 's/^\.\.\. \([A-Za-z0-9_.+-]*\).*/\1/p' -e 's/^\([A-Za-z0-9_.+-]*\): phony$/\1/p' <<< "$help"
}

if [[ $do_build -eq 1 ]]; then
  # Two passes: a CMakeLists.txt changed during the build re-runs CMake and may add tests.
  for pass in 1 2; do
    # Only names that are build targets (a test may run e.g. `cmake -P`).
    known=$(build_targets)
    mapfile -t targets < <(list_targets | sort -u | grep -Fx -f <(printf '%s\n' "$known"))
    nice cmake --build "$build" -j"$jobs" --target "${targets[@]}" > "$build/sanitize.build.log" 2>&1 ||
      { tail -50 "$build/sanitize.build.log" >&2; die "build failed (full log: $build/sanitize.build.log)"; }
    mapfile -t again < <(cd "$build" && ctest -N "${select[@]}" | sed -n 's/^ *Test *#[0-9]*: *//p')
    [[ "${again[*]}" == "${tests[*]}" ]] && break
    tests=("${again[@]}")
  done
fi
built=$(date +%s)

# halt_on_error: the first report ends the process with a failure (UBSan only warns by default);
# print_stacktrace: where the undefined behaviour happened. Leak detection stays on (ASan default).
export ASAN_OPTIONS="halt_on_error=1:abort_on_error=0:detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
if [[ $dds -eq 1 ]]; then export ASAN_OPTIONS="$ASAN_OPTIONS:new_delete_type_mismatch=0"; fi
# Third party: OpenCV's gPhoto2 camera autodetection (cv::VideoCapture::open(index) ->
# gp_camera_autodetect -> libusb_get_device_list) leaks ~22 KB per attempt, seen when a test opens a
# camera index that does not exist; the fast unwinder cannot see past libusb, so a suppression
# cannot match it. CI has no gPhoto2 camera: the backend is switched off for the sanitized run.
export OPENCV_VIDEOIO_PRIORITY_GPHOTO2=0
# Third-party leak suppressions for the DDS tests only (see the file).
if [[ $dds -eq 1 ]]; then
  export LSAN_OPTIONS="suppressions=$repo/bringup/sanitize_dds.lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
fi

log="$build/sanitize.log"
set +e
(cd "$build" && ctest "${select[@]}" --output-on-failure --timeout 900 -j"$test_jobs") 2>&1 | tee "$log"
rc=${PIPESTATUS[0]}
set -e
end=$(date +%s)

# Reports of child processes can hide behind a passing test: scan every test's output too.
reports=$(grep -c -E "ERROR: (AddressSanitizer|LeakSanitizer)|runtime error:|SUMMARY: (AddressSanitizer|UndefinedBehaviorSanitizer)" \
  "$log" "$build"/Testing/Temporary/LastTest.log 2>/dev/null | awk -F: '{s += $NF} END {print s + 0}' || true)
echo "sanitize.sh: build $((built - start)) s, tests $((end - built)) s, ctest exit $rc, sanitizer report lines $reports"
if [[ $rc -ne 0 || $reports -ne 0 ]]; then
  echo "sanitize.sh: FAILED (see $log and $build/Testing/Temporary/LastTest.log)" >&2
  exit 1
fi
echo "sanitize.sh: clean"
