#!/usr/bin/env bash
# fuzz.sh — builds the libFuzzer targets of tests/fuzz with clang in a separate build dir and runs
# each one for a bounded time on its seed corpus (shipped files) and its committed reproducers
# (tests/fuzz/regressions/<target>/). Exits non-zero if any target crashes, reports a sanitizer
# error, or finds an undocumented exception; the input is saved under <build>/artifacts/<target>/
# and replayed once with its message. See tests/fuzz/README.md.
set -euo pipefail

usage() {
  cat <<'USAGE'
usage: fuzz.sh [--time SECONDS] [--seed N] [--build-dir DIR] [--jobs N] [--no-build]
               [--configure-only] [--keep-going] [TARGET...]

Builds (clang, -fsanitize=fuzzer,address,undefined) and runs the Reflex fuzz targets.

  --time SECONDS   fuzzing time per target (default 20; -max_total_time)
  --seed N         libFuzzer's random seed (-seed; default: a new one each run). With a seed, a run
                   replays the same inputs in the same order, as far as the time allows (CI)
  --build-dir DIR  build folder (default: <repo>/build-fuzz)
  --jobs N         build jobs (default 2)
  --no-build       use an existing build
  --configure-only configure the build folder (clang, sanitizers, REFLEX_FUZZ=ON) and stop; also
                   used by sanitize.sh --clang-fuzz, so that one folder holds the fuzz targets and
                   the sanitized tests (bringup/test.sh)
  --keep-going     survey mode: do not stop at the first finding (libFuzzer -fork=1
                   -ignore_crashes=1); every distinct crash input is kept in the artifacts folder
  TARGET...        only these targets (default: all, e.g. fuzz_urdf fuzz_idl)
Exit status: 0 no finding; 1 a target found a crash; 2 bad arguments, missing clang, build failure.
USAGE
}

die() { echo "fuzz.sh: error: $*" >&2; exit 2; }

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$repo/build-fuzz"
seconds=20
jobs=2
do_build=1
keep_going=0
seed=""
configure_only=0
only=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    -h|--help) usage; exit 0 ;;
    --time)
      [[ $# -ge 2 && "$2" =~ ^[1-9][0-9]*$ ]] || die "--time '${2:-}' is not a positive number of seconds"
      seconds="$2"; shift 2 ;;
    --build-dir) [[ $# -ge 2 ]] || die "--build-dir needs a folder"; build="$2"; shift 2 ;;
    --jobs)
      [[ $# -ge 2 && "$2" =~ ^[1-9][0-9]*$ ]] || die "--jobs '${2:-}' is not a positive integer"
      jobs="$2"; shift 2 ;;
    --no-build) do_build=0; shift ;;
    --configure-only) configure_only=1; shift ;;
    --keep-going) keep_going=1; shift ;;
    --seed)
      [[ $# -ge 2 && "$2" =~ ^[1-9][0-9]*$ ]] || die "--seed '${2:-}' is not a positive integer"
      seed="$2"; shift 2 ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *) only+=("$1"); shift ;;
  esac
done

cc=$(command -v clang || command -v clang-14 || true)
cxx=$(command -v clang++ || command -v clang++-14 || true)
[[ -n "$cc" && -n "$cxx" ]] || die "clang not found (Debian packages clang-14 libclang-rt-14-dev)"

start=$(date +%s)
if [[ $do_build -eq 1 ]]; then
  mkdir -p "$build" || die "cannot create the build folder '$build'"
  flags="-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer -gline-tables-only"
  # -O1 and line tables only (not RelWithDebInfo's -O2 -g): what ASan recommends, and a shorter
  # build (CI builds this folder from scratch on every run). Ninja for a new folder: it builds the
  # many targets named on one `cmake --build --target` line in parallel, where CMake's Makefiles
  # build them one after the other (.NOTPARALLEL), one core idle most of the time.
  generator=()
  if [[ ! -f "$build/CMakeCache.txt" ]] && command -v ninja > /dev/null; then generator=(-G Ninja); fi
  CC="$cc" CXX="$cxx" cmake -S "$repo" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DREFLEX_FUZZ=ON \
    "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -DNDEBUG" "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -DNDEBUG" \
    -DREFLEX_BUILD_BENCHMARKS=OFF "-DCMAKE_C_FLAGS=$flags" "-DCMAKE_CXX_FLAGS=$flags" \
    > "$build/fuzz.configure.log" 2>&1 ||
    { tail -30 "$build/fuzz.configure.log" >&2; die "configure of '$build' failed"; }
fi
[[ $configure_only -eq 0 ]] || { echo "fuzz.sh: configured $build"; exit 0; }
cache="$build/CMakeCache.txt"
[[ -f "$cache" ]] || die "'$build' is not a configured build folder"
entries=$(sed -n 's/^REFLEX_FUZZ_TARGETS:INTERNAL=//p' "$cache")
[[ -n "$entries" ]] || die "no fuzz targets in '$build' (is tests/fuzz added by tests/CMakeLists.txt?)"

declare -A seeds
names=()
IFS=';' read -r -a list <<< "$entries"
for e in "${list[@]}"; do
  name="${e%%|*}"
  seeds[$name]="${e#*|}"
  if [[ ${#only[@]} -eq 0 ]] || printf '%s\n' "${only[@]}" | grep -qx "$name"; then names+=("$name"); fi
done
for o in "${only[@]}"; do
  [[ -n "${seeds[$o]+x}" ]] || die "unknown fuzz target '$o' (known: ${!seeds[*]})"
done

if [[ $do_build -eq 1 ]]; then
  targets=("${names[@]}")
  if printf '%s\n' "${names[@]}" | grep -qx fuzz_idl; then targets+=(fuzz_idl_seeds); fi
  nice cmake --build "$build" -j"$jobs" --target "${targets[@]}" > "$build/fuzz.build.log" 2>&1 ||
    { tail -40 "$build/fuzz.build.log" >&2; die "build failed (full log: $build/fuzz.build.log)"; }
fi
built=$(date +%s)

export ASAN_OPTIONS="halt_on_error=1:detect_leaks=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
# Third-party leaks, each explained in the file (urdfdom's rejected half-built tree).
export LSAN_OPTIONS="suppressions=$repo/bringup/fuzz.lsan.supp${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
failed=()
summary=()
for t in "${names[@]}"; do
  corpus="$build/corpus/$t"
  artifacts="$build/artifacts/$t"
  mkdir -p "$corpus" "$artifacts"
  IFS=',' read -r -a files <<< "${seeds[$t]}"
  for f in "${files[@]}"; do [[ -n "$f" ]] && cp -n "$f" "$corpus/" ; done
  if [[ "$t" == fuzz_idl ]]; then "$build/bin/fuzz_idl_seeds" "$corpus"; fi
  dirs=("$corpus")
  if [[ -d "$repo/tests/fuzz/regressions/$t" ]]; then dirs+=("$repo/tests/fuzz/regressions/$t"); fi
  log="$build/fuzz_$t.log"
  echo "fuzz.sh: $t for ${seconds} s (corpus $corpus)"
  t_start=$(date +%s)
  extra=()
  if [[ $keep_going -eq 1 ]]; then extra=(-fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1); fi
  if [[ -n "$seed" ]]; then extra+=(-seed="$seed"); fi
  marker="$artifacts/.run-start"
  touch "$marker"
  set +e
  "$build/bin/$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -close_fd_mask=3 \
    -print_final_stats=1 -artifact_prefix="$artifacts/" "${extra[@]}" "${dirs[@]}" > "$log" 2>&1
  rc=$?
  set -e
  # In survey mode libFuzzer exits 0 even after crashes: the inputs saved by THIS run are the
  # findings (not those of earlier runs still in the folder).
  if [[ $keep_going -eq 1 && $rc -eq 0 && -n "$(find "$artifacts" -name 'crash-*' -newer "$marker")" ]]; then rc=1; fi
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  summary+=("$t: ${execs:-?} runs in $(($(date +%s) - t_start)) s, coverage ${cov:-?} edges, exit $rc")
  if [[ $rc -ne 0 ]]; then
    failed+=("$t")
    crash=$(find "$artifacts" -type f ! -name .run-start -newer "$marker" -printf '%T@ %p\n' | sort -n | tail -1 | cut -d' ' -f2-)
    echo "fuzz.sh: $t FOUND A PROBLEM (exit $rc); log $log; input ${crash:-none}" >&2
    grep -a -E "ERROR:|runtime error|FUZZ FINDING|SUMMARY" "$log" | head -5 >&2 || true
    if [[ -n "$crash" ]]; then
      echo "fuzz.sh: replay of $crash:" >&2
      "$build/bin/$t" "$crash" 2>&1 | grep -a -E "FUZZ FINDING|ERROR:|runtime error|SUMMARY|#[0-3] " | head -12 >&2 || true
      # A CI machine's build folder is gone after the run: the log keeps a small input.
      if [[ $(stat -c %s "$crash") -le 8192 ]]; then
        echo "fuzz.sh: the input, base64 (base64 -d > $(basename "$crash")):" >&2
        base64 -w 100 "$crash" >&2
      fi
    fi
  fi
done
end=$(date +%s)
printf 'fuzz.sh: %s\n' "${summary[@]}"
echo "fuzz.sh: build $((built - start)) s, fuzzing $((end - built)) s"
if [[ ${#failed[@]} -gt 0 ]]; then
  echo "fuzz.sh: FINDINGS in: ${failed[*]} (reproducers in $build/artifacts/; commit them to tests/fuzz/regressions/<target>/ with the fix)" >&2
  exit 1
fi
echo "fuzz.sh: no finding"
