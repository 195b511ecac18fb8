#!/usr/bin/env python3
"""Checks that the real-time core of control/ depends on nothing above it.

Usage: control_layers.py [--self-test] SOURCE_DIR

The core is the library reflex_control_core (its sources are read from control/CMakeLists.txt);
its public headers are the reflex/control headers those sources include, followed transitively.
None of them may include a header of the layer above (the robot description, the mesh fit, pair
sampling, robot set-up, the scenarios) or a header of assimp, qhull or urdfdom. Exit 0 when the
arrows point one way, 1 naming each include that does not, 2 on bad usage. --self-test first
checks that a core source including scenarios.hpp is caught (in a copy of control/ made for it).
"""
import os
import re
import shutil
import sys
import tempfile

UPPER = {
    "reflex/control/urdf_loader.hpp", "reflex/control/mesh_fit.hpp", "reflex/control/pair_sampling.hpp",
    "reflex/control/robot_setup.hpp", "reflex/control/scenarios.hpp", "fit_inputs.hpp", "urdf_audit.hpp",
}
FOREIGN = re.compile(r"^(assimp/|libqhull|urdf_model/|urdf_parser/|tinyxml2)")
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.M)


def core_sources(root):
    text = open(os.path.join(root, "control", "CMakeLists.txt")).read()
    m = re.search(r"add_library\(reflex_control_core\s+([^)]*)\)", text)
    if not m:
        raise SystemExit("control_layers: error: no add_library(reflex_control_core ...) in control/CMakeLists.txt")
    return [os.path.join(root, "control", s) for s in m.group(1).split()]


def resolve(root, including, name):
    for base in (os.path.dirname(including), os.path.join(root, "control", "include"),
                 os.path.join(root, "control", "src")):
        path = os.path.join(base, name)
        if os.path.isfile(path):
            return path
    return None


def check(root):
    """The includes of the core that point up, as lines, and the number of core files read."""
    pending = core_sources(root)
    seen, bad = set(), []
    while pending:
        path = pending.pop()
        if path in seen:
            continue
        seen.add(path)
        for name in INCLUDE.findall(open(path).read()):
            if name in UPPER or FOREIGN.match(name):
                bad.append(f"{os.path.relpath(path, root)}: includes {name}")
                continue
            found = resolve(root, path, name)
            if found and found.startswith(os.path.join(root, "control")):
                pending.append(found)
    return bad, len(seen)


def self_test(root):
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copytree(os.path.join(root, "control"), os.path.join(tmp, "control"))
        onboard = os.path.join(tmp, "control", "src", "onboard.cpp")
        with open(onboard, "a") as f:
            f.write('\n#include "reflex/control/scenarios.hpp"\n')
        bad, _ = check(tmp)
        if not any("onboard.cpp: includes reflex/control/scenarios.hpp" in b for b in bad):
            return f"self-test: an upward include in onboard.cpp was not reported (got {bad})"
    return ""


def main():
    args = [a for a in sys.argv[1:] if a != "--self-test"]
    if len(args) != 1 or not os.path.isdir(args[0]):
        print(__doc__, file=sys.stderr)
        return 2
    root = os.path.abspath(args[0])
    if "--self-test" in sys.argv[1:]:
        why = self_test(root)
        if why:
            print(f"control_layers: {why}", file=sys.stderr)
            return 1
    bad, nseen = check(root)
    for line in bad:
        print(line)
    if bad:
        print(f"control_layers: {len(bad)} include(s) from the core to the layer above or its libraries",
              file=sys.stderr)
        return 1
    print(f"control_layers: {nseen} core files, every include points down")
    return 0


if __name__ == "__main__":
    sys.exit(main())
