#!/usr/bin/env python3
"""Every Reflex program answers the same way (reflex/common/error.hpp, docs/tools.md "Exit codes"):

  --help                      exit 0, its text on stdout
  an option it does not know  exit 2, the option named on stderr
  a file that does not exist  exit 2, one line "<program>: error: ..." naming the path

Every reflex_* executable in the build's bin folder is run (the test helpers listed below aside), so
a new program that answers otherwise, or is missing from the table, fails here.

usage: exit_codes_test.py BIN_DIR
"""
import os
import subprocess
import sys
import tempfile

MISSING = "/nonexistent/reflex-exit-code-test"

# Built beside the programs, used only by tests; not installed.
TEST_HELPERS = {"reflex_fault_source", "reflex_latency_bench", "reflex_modules_object_publisher",
                "reflex_test_robot", "reflex_trigger_bench", "reflex_plot_sim.py"}


def bad_file_args(out):
    """Per program: the arguments of a run naming a file that does not exist (MISSING...)."""
    return {
        "reflex_controller": ["--urdf", MISSING + ".urdf", "--duration", "1"],
        "reflex_mujoco": ["--urdf", MISSING + ".urdf", "--duration", "1"],
        "reflex_setup": [MISSING + ".urdf", "--out", os.path.join(out, "setup")],
        "reflex_sim": ["crossing_arms", "--urdf", MISSING + ".urdf", "--out", os.path.join(out, "sim")],
        "reflex_inspect": [MISSING + ".urdf"],
        "reflex_fit": [MISSING + ".urdf"],
        "reflex_behavior": ["--config", MISSING + ".yaml"],
        "reflex_record": ["info", MISSING + ".mcap"],
        "reflex_play": [MISSING + ".mcap"],
        "reflex_bus": ["hz", "--profiles", MISSING + ".xml", "--window", "0.1"],
        "reflex_view": ["--urdf", MISSING + ".urdf", "--port", "0", "--duration", "1"],
        "reflex_scene": ["--log", MISSING + ".csv", "--at", "1", "--out", os.path.join(out, "scene.js")],
        "reflex_vision_record": ["--from-files", MISSING + ".left.mp4", MISSING + ".right.mp4",
                                 "--calib-left", MISSING + ".left.yaml", "--calib-right", MISSING + ".right.yaml",
                                 "--objects", MISSING + ".objects.yaml", "--out", os.path.join(out, "session")],
        "reflex_calibrate": ["calibrate", "--pairs", MISSING, "--out", os.path.join(out, "calibration")],
        "reflex_detect": [MISSING + ".png"],
        "reflex_vision": ["--session", MISSING, "--duration", "1"],
        "reflex_make_session": ["--script", MISSING + ".yaml", "--out", os.path.join(out, "made")],
    }


def run(path, args):
    env = dict(os.environ, REFLEX_DOMAIN_ID="231")  # nothing here reaches DDS traffic; a free domain anyway
    p = subprocess.run([path] + args, capture_output=True, text=True, timeout=120, env=env,
                       stdin=subprocess.DEVNULL)
    return p.returncode, p.stdout, p.stderr


def main():
    bin_dir = sys.argv[1]
    failures = []
    found = sorted(f for f in os.listdir(bin_dir) if f.startswith("reflex_") and f not in TEST_HELPERS)
    with tempfile.TemporaryDirectory() as out:
        table = bad_file_args(out)
        for name in sorted(set(found) - set(table)):
            failures.append(f"{name}: a program this test does not know; add it to bad_file_args()")
        for name in sorted(set(table) - set(found)):
            failures.append(f"{name}: not built in {bin_dir}")
        for name in sorted(set(table) & set(found)):
            path = os.path.join(bin_dir, name)
            code, so, se = run(path, ["--help"])
            if code != 0 or not so.strip():
                failures.append(f"{name} --help: exit {code}, {len(so)} bytes on stdout")
            args = table[name]
            # After a whole command line, so that no required option is missing (CLI11 says that first).
            code, so, se = run(path, args + ["--no-such-option"])
            if code != 2 or "--no-such-option" not in se:
                failures.append(f"{name} ... --no-such-option: exit {code} (want 2, naming it), "
                                f"stderr: {se.strip()[:300]!r}")
            code, so, se = run(path, args)
            line = f"{name}: error: "  # a subcommand may name itself too: "reflex_record info: error: "
            said = [x for x in se.splitlines() if x.startswith(name) and ": error: " in x and MISSING in x]
            if code != 2 or not said:
                failures.append(f"{name} {' '.join(args)}: exit {code} (want 2 and '{line}... {MISSING}...'), "
                                f"stderr: {se.strip()[-400:]!r}")
            print(f"{name}: --help 0, unknown option 2, missing file 2" if not failures or
                  not failures[-1].startswith(name) else f"{name}: FAILED", flush=True)
    for f in failures:
        print("FAIL: " + f)
    print(f"{len(table)} programs, {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
