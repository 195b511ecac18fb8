#!/usr/bin/env python3
"""Checks that the three libraries of control/ depend on each other one way only.

Usage: control_layers.py [--self-test] SOURCE_DIR

control/CMakeLists.txt builds three layers (their sources are read from it):
  reflex_control_core   the real-time core: may use the core only, and no assimp, qhull, urdfdom, tinyxml2;
  reflex_robot_setup    robot description, fit, set-up: may use itself and the core;
  reflex_scenarios      the experiments: may use itself and the core, and none of those libraries.
A header belongs to the layer whose library builds the source of the same name (scenarios.hpp to the
one that builds scenarios.cpp); fit_inputs.hpp (the fit's private header) to reflex_robot_setup; a
header without a source (geometry.hpp) to the core. Each layer's sources are followed through their
control/ includes, transitively. Exit 0 when every include points to an allowed layer, 1 naming each
one that does not, 2 on bad usage. --self-test first checks, in copies of control/, that a core
source including scenarios.hpp and a scenario source including urdf_loader.hpp are both caught.
"""
import os
import re
import shutil
import sys
import tempfile

LAYERS = ("reflex_control_core", "reflex_robot_setup", "reflex_scenarios")
ALLOWED = {
    "reflex_control_core": {"reflex_control_core"},
    "reflex_robot_setup": {"reflex_control_core", "reflex_robot_setup"},
    "reflex_scenarios": {"reflex_control_core", "reflex_scenarios"},
}
EXTRA_OWNERS = {"fit_inputs.hpp": "reflex_robot_setup"}
FOREIGN = re.compile(r"^(assimp/|libqhull|urdf_model/|urdf_parser/|urdf_world/|tinyxml2)")
FOREIGN_ALLOWED = {"reflex_robot_setup"}
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', re.M)


def layer_sources(root):
    """{layer: [source paths]} from control/CMakeLists.txt."""
    text = open(os.path.join(root, "control", "CMakeLists.txt")).read()
    out = {}
    for layer in LAYERS:
        m = re.search(r"(?:add_library|reflex_control_layer)\(" + layer + r"\s+([^)]*)\)", text)
        if not m:
            raise SystemExit(f"control_layers: error: no reflex_control_layer({layer} ...) in control/CMakeLists.txt")
        out[layer] = [os.path.join(root, "control", s) for s in m.group(1).split()]
    return out


def owner_of(header_path, sources):
    stem = os.path.splitext(os.path.basename(header_path))[0]
    if os.path.basename(header_path) in EXTRA_OWNERS:
        return EXTRA_OWNERS[os.path.basename(header_path)]
    for layer, files in sources.items():
        if any(os.path.splitext(os.path.basename(f))[0] == stem for f in files):
            return layer
    return "reflex_control_core"


def resolve(root, including, name):
    for base in (os.path.dirname(including), os.path.join(root, "control", "include"),
                 os.path.join(root, "control", "src")):
        path = os.path.join(base, name)
        if os.path.isfile(path):
            return path
    return None


def check(root):
    """The includes that point to a layer not allowed, as lines, and the number of files read."""
    sources = layer_sources(root)
    bad, nread = [], 0
    for layer, files in sources.items():
        pending, seen = list(files), set()
        while pending:
            path = pending.pop()
            if path in seen:
                continue
            seen.add(path)
            for name in INCLUDE.findall(open(path).read()):
                if FOREIGN.match(name):
                    if layer not in FOREIGN_ALLOWED:
                        bad.append(f"{os.path.relpath(path, root)} ({layer}): includes {name}")
                    continue
                found = resolve(root, path, name)
                if not found or not found.startswith(os.path.join(root, "control")):
                    continue
                owner = owner_of(found, sources)
                if owner not in ALLOWED[layer]:
                    bad.append(f"{os.path.relpath(path, root)} ({layer}): includes {name} of {owner}")
                    continue
                pending.append(found)
        nread += len(seen)
    return bad, nread


def self_test(root):
    cases = (("onboard.cpp", "reflex/control/scenarios.hpp"), ("scenarios.cpp", "reflex/control/urdf_loader.hpp"))
    for source, header in cases:
        with tempfile.TemporaryDirectory() as tmp:
            shutil.copytree(os.path.join(root, "control"), os.path.join(tmp, "control"))
            with open(os.path.join(tmp, "control", "src", source), "a") as f:
                f.write(f'\n#include "{header}"\n')
            bad, _ = check(tmp)
            if not any(f"{source} (" in b and f"includes {header}" in b for b in bad):
                return f"self-test: {source} including {header} was not reported (got {bad})"
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
    bad, nread = check(root)
    for line in bad:
        print(line)
    if bad:
        print(f"control_layers: {len(bad)} include(s) against the layering", file=sys.stderr)
        return 1
    print(f"control_layers: {nread} files of {len(LAYERS)} layers, every include points to an allowed layer")
    return 0


if __name__ == "__main__":
    sys.exit(main())
