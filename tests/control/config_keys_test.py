#!/usr/bin/env python3
"""Keeps control/docs/configuration.md complete: every key string the project's YAML readers look
up (found here by reading the readers' source, not by a list kept by hand) must appear in the page
as `key` (in backticks). Fails naming each missing key and the reader it came from, and when a
reader's patterns find fewer than 3 keys (a reader rewritten so that this test no longer sees it).

Readers and how their keys are found (regular expressions over the source). Every C++ reader reads
through common::ConfigNode (idl/common/include/reflex/common/yaml_reader.hpp), so the same patterns
find them all: its getters .string("x") .number("x") .at("x") ... and rejectUnknown({...}) lists.
  controller   control/src/controller_config.cpp   {"key", &p.x}, getters, rejectUnknown
  collision    control/src/urdf_loader.cpp         rejectUnknown, getters
  fit overlay  control/src/fit_overlay.cpp         getters, point("x", ...)
  hg joint map control/node/src/unitree_hg.cpp     rejectUnknown, getters
  behavior     modules/src/*.cpp                   rejectUnknown({...}) lists, getters
  vision       vision/src/{session,session_maker,calibration,calibration_images,object_map}.cpp
               getters, rejectUnknown, readRosMatrix(root, "x", ...), file("x", ...)
  launch       bringup/launch.py                   .get("x"), ["x"], the TOP_KEYS / PROCESS_KEYS sets
Usage: config_keys_test.py SOURCE_DIR [--list]
"""
import re
import sys
from pathlib import Path

PATTERNS = [
    r'\{"([a-z_][a-z0-9_]*)",\s*&p\.',
    r'\b(?:key|fk)\s*==\s*"([a-z_][a-z0-9_]*)"',
    r'\[\s*"([a-z_][a-z0-9_]*)"\s*\]',
    r'\brequire\w*\([^,()]+,\s*"([a-z_][a-z0-9_]*)"',
    r'\.(?:string|requiredString|number|requiredNumber|integer|boolean|choice|vec3|strings|child|list|raw|has|at)\(\s*"([a-z_][a-z0-9_]*)"',
    r'\.get\(\s*"([a-z_][a-z0-9_]*)"',
    r'\b(?:file|point)\(\s*"([a-z_][a-z0-9_]*)"',
    r'\breadRosMatrix\([^,()]+,\s*"([a-z_][a-z0-9_]*)"',
]
# Dictionary look-ups in the readers that are not keys of a file (the launcher's own bookkeeping).
NOT_FILE_KEYS = {"launch": {"why"}}

READERS = {
    "controller": ["control/src/controller_config.cpp"],
    "collision": ["control/src/urdf_loader.cpp"],
    "fit overlay": ["control/src/fit_overlay.cpp"],
    "unitree_hg joint map": ["control/node/src/unitree_hg.cpp"],
    "behavior": "modules/src/*.cpp",
    "vision": ["vision/src/session.cpp", "vision/src/session_maker.cpp", "vision/src/calibration.cpp",
               "vision/src/calibration_images.cpp", "vision/src/object_map.cpp"],
    "launch": ["bringup/launch.py"],
}


def keys_of(text):
    found = set()
    for pat in PATTERNS:
        found.update(re.findall(pat, text))
    for block in re.findall(r'rejectUnknown\(\{([^}]*)\}', text) + re.findall(r'\b[A-Z_]*KEYS\s*=\s*\{([^}]*)\}', text):
        found.update(re.findall(r'"([a-z_][a-z0-9_]*)"', block))
    return found


def main():
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    root = Path(sys.argv[1])
    import os
    os.chdir(root)
    page = (root / "control/docs/configuration.md").read_text()
    documented = set(re.findall(r'`([a-z_][a-z0-9_]*)`', page))
    missing = []
    total = 0
    for reader, files in READERS.items():
        if isinstance(files, str):  # a glob, relative to the source folder
            files = sorted(str(p) for p in Path(".").glob(files))
        keys = set()
        for f in files:
            if not Path(f).exists():
                missing.append(f"{reader}: reader {f} not found (update this test)")
                continue
            keys |= keys_of(Path(f).read_text())
        keys -= NOT_FILE_KEYS.get(reader, set())
        if len(keys) < 3:
            missing.append(f"{reader}: only {len(keys)} keys found in {files}: the patterns no longer match the reader")
        total += len(keys)
        if "--list" in sys.argv:
            print(f"{reader}: {' '.join(sorted(keys))}")
        for k in sorted(keys):
            if k not in documented:
                missing.append(f"{reader}: key '{k}' (read in {', '.join(files) if len(files) < 3 else 'modules/src'}) "
                               "is not in control/docs/configuration.md")
    if missing:
        print("\n".join(missing))
        print(f"FAILED: {len(missing)} of {total} keys undocumented")
        return 1
    print(f"ok: {total} keys of {len(READERS)} readers documented")
    return 0


if __name__ == "__main__":
    sys.exit(main())
