#!/usr/bin/env python3
"""The README's commands, taken from README.md itself so that the page and the test cannot drift:

  - its first fenced block holds exactly the two commands, bringup/demo.sh and bringup/test.sh;
  - .ci/run runs the README's test command and nothing else;
  - bringup/test.sh --help and bringup/demo.sh --help answer (exit 0, usage text);
  - bringup/demo.sh --sim-only, the README's demo command without the flagship replay (the flagship
    itself is flagship_test's), runs to the end and prints the first line the README's "Expected
    output" shows; the line only the full run prints is printed by demo.sh as the README shows it;
  - the summary line the README shows for bringup/test.sh is the one test.sh writes (every fixed
    part of it, in order, is in the summary test.sh assembles).

usage: readme_commands_test.py SOURCE_DIR BUILD_DIR
"""
import os
import re
import subprocess
import sys


def fenced_blocks(text):
    """The fenced code blocks of a Markdown text: (info string, lines)."""
    blocks, current, info = [], None, ""
    for line in text.splitlines():
        if line.startswith("```"):
            if current is None:
                current, info = [], line[3:].strip()
            else:
                blocks.append((info, current))
                current = None
        elif current is not None:
            current.append(line)
    return blocks


def main():
    src, build = sys.argv[1], sys.argv[2]
    failures = []
    with open(os.path.join(src, "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    blocks = fenced_blocks(readme)
    commands = [line.split("#")[0].strip() for line in blocks[0][1] if line.strip()] if blocks else []
    if [c.split()[0] for c in commands] != ["bringup/demo.sh", "bringup/test.sh"]:
        failures.append("README.md's first fenced block is not the two commands demo.sh, test.sh: %r" % commands)
        commands = ["bringup/demo.sh", "bringup/test.sh"]
    demo_cmd, test_cmd = commands[0], commands[1]

    with open(os.path.join(src, ".ci", "run"), encoding="utf-8") as fh:
        ci = [line.strip() for line in fh if line.strip() and not line.lstrip().startswith("#")]
    ran = [line for line in ci if not line.startswith(("set ", "cd "))]
    if ran != ["exec " + test_cmd]:
        failures.append(".ci/run does not run exactly the README's test command '%s': %r" % (test_cmd, ran))

    for cmd in (demo_cmd, test_cmd):
        p = subprocess.run([os.path.join(src, cmd.split()[0]), "--help"], capture_output=True, text=True, timeout=60)
        if p.returncode != 0 or "Usage" not in p.stdout + p.stderr:
            failures.append("%s --help: exit %d, no usage text: %r" % (cmd, p.returncode, (p.stdout + p.stderr)[:300]))
        else:
            print("%s --help: exit 0" % cmd, flush=True)

    # The expected output the README shows: the text block after "## Expected output".
    expected = readme.split("## Expected output", 1)[1] if "## Expected output" in readme else ""
    text_blocks = [lines for info, lines in fenced_blocks(expected) if info == "text"]
    if len(text_blocks) < 2:
        failures.append("README.md's 'Expected output' has not the two text blocks (demo.sh, test.sh)")
        text_blocks = [[], []]
    demo_lines, test_lines = text_blocks[0], text_blocks[1]

    env = dict(os.environ, REFLEX_BUILD_DIR=build)
    print("running %s --sim-only (set-up, then reflex_sim all with and without avoidance)" % demo_cmd, flush=True)
    p = subprocess.run([os.path.join(src, demo_cmd.split()[0]), "--sim-only"], capture_output=True, text=True,
                       timeout=900, env=env, cwd=src)
    out = p.stdout.splitlines()
    if p.returncode != 0:
        failures.append("%s --sim-only: exit %d: %s" % (demo_cmd, p.returncode, (p.stdout + p.stderr)[-800:]))
    elif not demo_lines or demo_lines[0] not in out:
        failures.append("%s --sim-only did not print the README's first expected line %r; its last lines: %r"
                        % (demo_cmd, demo_lines[:1], out[-5:]))
    else:
        print("demo.sh --sim-only: exit 0, printed %r" % demo_lines[0], flush=True)
    with open(os.path.join(src, "bringup", "demo.sh"), encoding="utf-8") as fh:
        demo_src = fh.read()
    for line in demo_lines[1:]:
        if line not in demo_src:
            failures.append("demo.sh never prints the README's expected line %r" % line)

    # test.sh's summary: the README's line with "…" for the figures; every fixed part in the order
    # test.sh assembles them.
    with open(os.path.join(src, "bringup", "test.sh"), encoding="utf-8") as fh:
        test_src = fh.read()
    items = re.findall(r'"([^"]*)"', " ".join(re.findall(r'summary\+=\((.*)\)', test_src)))
    items = [item for item in items if "skipped" not in item]  # the --no-hygiene variant
    parts = [part.strip(" ,") for item in items
             for part in re.split(r"\$\(\([^)]*\)\)|\$\{?\w+\}?", item) if part.strip(" ,")]
    readme_line = test_lines[0] if test_lines else ""
    pos = 0
    for fixed in parts:
        at = readme_line.find(fixed, pos)
        if at < 0:
            failures.append("the README's test.sh summary line %r lacks %r (in test.sh's summary) at its place"
                            % (readme_line, fixed))
            break
        pos = at + len(fixed)
    if not readme_line.startswith("test.sh: ") or not readme_line.endswith(", exit 0") or \
            'echo "test.sh: $line, exit $status"' not in test_src:
        failures.append("the README's test.sh summary line %r is not 'test.sh: <summary>, exit 0' as test.sh writes it"
                        % readme_line)

    for f in failures:
        print("FAIL: " + f)
    print("%d failures" % len(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
