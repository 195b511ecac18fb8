#!/usr/bin/env bash
# Reflex set-up: installs every Debian 12 package the project and its tests use (only the missing
# ones), then configures and builds the project in Release with both cores.
# Idempotent: running it twice installs nothing the second time and rebuilds only what changed.
#
# Usage: bringup/setup.sh [--no-build] [--build-dir DIR] [--help]
#   REFLEX_BUILD_DIR   build folder (default: <repo>/build)
#   REFLEX_CMAKE_ARGS  extra arguments for the CMake configure step
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${REFLEX_BUILD_DIR:-$here/build}
do_build=1
while [ $# -gt 0 ]; do
  case "$1" in
    --no-build) do_build=0 ;;
    --build-dir) build_dir=$2; shift ;;
    -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "setup.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
  esac
  shift
done

# One list, grouped by who needs it. Keep it in step with find_package() calls in CMakeLists.txt.
packages=(
  # toolchain
  build-essential cmake pkg-config git ccache
  # bus: Fast DDS 2.9 + code generator (needs a JRE) + discovery server CLI
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools default-jre-headless
  # bus: checks the DDS-Security material itself (OpenSSL libcrypto, idl/bus/src/security.cpp)
  libssl-dev
  # control: math, robot description, configuration
  libeigen3-dev liburdfdom-dev liburdfdom-headers-dev libyaml-cpp-dev libtinyxml2-dev libcli11-dev
  # vision
  libapriltag-dev libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev
  libopencv-videoio-dev libopencv-calib3d-dev libopencv-contrib-dev ffmpeg
  # tests and benchmarks: independent answers and a second DDS vendor
  googletest libgtest-dev libgmock-dev libbenchmark-dev libfcl-dev liborocos-kdl-dev
  libkdl-parser-dev cyclonedds-dev cyclonedds-tools
  # OpenCV's own stereo sample pairs (examples/data/left01.jpg ...): real images for the calibration test
  opencv-doc
  # multi-host tests and reports
  iproute2 python3 python3-matplotlib python3-numpy python3-yaml
  # DDS-Security test credentials (bringup/security/make_security.sh); fuzzing and sanitized tests
  # (bringup/fuzz.sh, sanitize.sh --clang-fuzz, run by test.sh)
  openssl clang-14 libclang-rt-14-dev ninja-build
  # the C++ style check (.clang-format, tests/hygiene/format_check.py)
  clang-format-14
  # leak reproducers fail in every build, not only under LeakSanitizer (tests/fuzz/CMakeLists.txt)
  valgrind
  # the robot boundary: the physics-simulated robot (control/mujoco)
  libmujoco-dev
  # your own robot description: meshes, convex hulls
  libassimp-dev assimp-testmodels libqhull-dev
  # recordings and the live view: MCAP chunk compression, WebSocket, JSON, a real browser
  libzstd-dev liblz4-dev libwebsocketpp-dev libboost-dev nlohmann-json3-dev
  chromium chromium-headless-shell
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup.sh: installing ${#missing[@]} missing package(s): ${missing[*]}"
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup.sh: all ${#packages[@]} packages already installed"
fi

# Node.js + npm: this image may bring its own (Node 20); a fresh Debian 12 gets Node 18 + npm 9 from
# apt. Installed only when missing, so an existing Node is never replaced.
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  echo "setup.sh: installing nodejs and npm from Debian"
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends nodejs npm
fi
# JavaScript packages (bringup/web/package.json), exactly the versions of the committed lock file.
# Skipped when node_modules already matches the lock file.
web=$here/bringup/web
if ! cmp -s "$web/package-lock.json" "$web/node_modules/.package-lock.json" 2>/dev/null \
   && ! (cd "$web" && npm ls --depth=0 >/dev/null 2>&1); then
  echo "setup.sh: installing the JavaScript packages of bringup/web (npm ci)"
  (cd "$web" && npm ci --no-audit --no-fund --loglevel=error)
else
  echo "setup.sh: JavaScript packages of bringup/web already installed"
fi

[ "$do_build" -eq 1 ] || exit 0

echo "setup.sh: configuring and building in $build_dir (Release, $(nproc) jobs)"
# shellcheck disable=SC2086
cmake -S "$here" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release ${REFLEX_CMAKE_ARGS:-}
cmake --build "$build_dir" -j"$(nproc)"
