#!/usr/bin/env python3
"""Checks that every C/C++ source of the checkout is formatted as the committed .clang-format says.

Usage: format_check.py [--self-test] [--fix] [--clang-format EXE] SOURCE_DIR

The sources are the git-tracked *.c, *.h, *.cpp, *.hpp files (every file when SOURCE_DIR is not a git
checkout: the *.c/.h/.cpp/.hpp under it, build folders left out). They are run through
`clang-format --dry-run --Werror --style=file` in batches; a file it would change is named with the
first line it would change. --fix rewrites those files in place instead. --self-test first checks that a badly
formatted file is caught, so the check cannot pass by formatting nothing.
Exit: 0 all formatted, 1 a file is not, 2 bad usage or clang-format missing.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

EXTENSIONS = (".c", ".h", ".cpp", ".hpp")


def sources(root):
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z"], check=True, capture_output=True).stdout
        files = [f for f in out.decode().split("\0") if f.endswith(EXTENSIONS)]
        if files:
            return sorted(files)
    except (OSError, subprocess.CalledProcessError):
        pass
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if not d.startswith(("build", ".", "node_modules"))]
        for name in filenames:
            if name.endswith(EXTENSIONS):
                found.append(os.path.relpath(os.path.join(dirpath, name), root))
    return sorted(found)


VIOLATION = re.compile(r"^(.+?):(\d+):\d+: (?:error|warning): code should be clang-formatted")
BATCH = 64  # files per clang-format process (one process per file costs a second per ten files)


def check(exe, root, fix):
    """Every source checked (clang-format --dry-run --Werror over batches of files, its .clang-format
    found from each file's folder up); the unformatted ones with their first differing line. With
    `fix` they are rewritten in place (clang-format -i) and still returned."""
    files = sources(root)
    bad = {}
    for k in range(0, len(files), BATCH):
        batch = files[k:k + BATCH]
        res = subprocess.run([exe, "--dry-run", "--Werror", "--style=file"] + batch, cwd=root, capture_output=True)
        found = False
        for line in res.stderr.decode(errors="replace").splitlines():
            m = VIOLATION.match(line)
            if m:
                found = True
                bad.setdefault(os.path.relpath(os.path.join(root, m.group(1)), root), int(m.group(2)))
        if res.returncode != 0 and not found:
            raise RuntimeError(f"{exe} failed: {res.stderr.decode(errors='replace').strip()[:500]}")
    if fix and bad:
        subprocess.run([exe, "-i", "--style=file"] + sorted(bad), cwd=root, check=True)
    return files, sorted(bad.items())


def self_test(exe, root):
    """A file with a wrong indent on line 3 (clang-format names the end of line 2 or line 3), next to a
    copy of the style, must be reported; after --fix it must pass."""
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copy(os.path.join(root, ".clang-format"), tmp)
        with open(os.path.join(tmp, "bad.cpp"), "w") as f:
            f.write("int f(int x) {\n  int y = x;\n      return y+1;\n}\n")
        _, bad = check(exe, tmp, fix=False)
        if [b[0] for b in bad] != ["bad.cpp"] or bad[0][1] not in (2, 3):
            return f"self-test: a file misindented on line 3 was not reported there (got {bad})"
        check(exe, tmp, fix=True)
        _, bad = check(exe, tmp, fix=False)
        if bad:
            return f"self-test: the file is still reported after --fix (got {bad})"
    return ""


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("source_dir")
    ap.add_argument("--clang-format", default="clang-format-14", help="the clang-format program (default clang-format-14)")
    ap.add_argument("--fix", action="store_true", help="rewrite unformatted files in place")
    ap.add_argument("--self-test", action="store_true", help="first check that a misformatted file is caught")
    a = ap.parse_args()
    exe = shutil.which(a.clang_format)
    if exe is None:
        print(f"format_check: error: '{a.clang_format}' not found (bringup/setup.sh installs clang-format-14)",
              file=sys.stderr)
        return 2
    root = os.path.abspath(a.source_dir)
    if not os.path.isfile(os.path.join(root, ".clang-format")):
        print(f"format_check: error: no .clang-format in {root}", file=sys.stderr)
        return 2
    if a.self_test:
        why = self_test(exe, root)
        if why:
            print(f"format_check: {why}", file=sys.stderr)
            return 1
    files, bad = check(exe, root, a.fix)
    for rel, line in bad:
        print(f"{rel}:{line}: {'reformatted' if a.fix else 'not formatted as .clang-format says'}")
    if bad and not a.fix:
        print(f"format_check: {len(bad)} of {len(files)} files differ; run: python3 tests/hygiene/format_check.py "
              f"--fix {a.source_dir}", file=sys.stderr)
        return 1
    print(f"format_check: {len(files)} files formatted" + (f" ({len(bad)} rewritten)" if a.fix else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
