#!/usr/bin/env python3
"""Function lengths of the project's own code: C++ (.cpp .hpp .h .c), Python and JavaScript.

  function_lengths.py [--limit N] [--top K] [--allow FILE] [ROOT]

Lists every function longer than --limit lines (120) outside tests/, generated code and third-party
folders, longest first, and exits 1 if one of them is not in --allow FILE or has grown past the
length written there. The allow file holds the functions not yet split, one per line:
"LENGTH PATH NAME" (a ratchet: a function may only shrink or leave it, and a new long one fails).
--top K prints the K longest functions whatever their length.

A function is counted from the line of its body's opening brace to the line of its closing brace
(Python: from `def` to its last line); lambdas and local classes count towards the function they
are written in. C++ and JavaScript are read by matching braces after comments and string literals
are blanked out; a brace that follows `)` (and qualifiers such as const, noexcept, override, a
trailing return type, a constructor's initialiser list) outside any function opens a function.
"""
import argparse
import ast
import os
import re
import sys

SOURCE_DIRS = ["control", "idl", "modules", "vision", "bringup"]
SKIP_DIRS = {"node_modules", "three", "build", "generated", "__pycache__", ".git"}
NOT_CALLS = {"if", "for", "while", "switch", "catch", "return", "sizeof", "decltype", "alignas", "function"}


def blank_comments_and_strings(src):
    """`src` with comments and string / character literals replaced by blanks (newlines kept)."""
    out = []
    i, n = 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            i = n if j < 0 else j
            continue
        if src.startswith("/*", i):
            j = src.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * src.count("\n", i, j))
            i = j
            continue
        if c == "R" and src[i + 1:i + 2] == '"' and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', src[i:i + 40])
            if m:
                end = ")" + m.group(1) + '"'
                j = src.find(end, i + m.end())
                j = n if j < 0 else j + len(end)
                out.append('""' + "\n" * src.count("\n", i, j))
                i = j
                continue
        if c in "\"'`" and not (c == "'" and i > 0 and src[i - 1].isalnum()):  # 1'000 is a digit separator
            j = i + 1
            while j < n and src[j] != c:
                if src[j] == "\\":
                    j += 1
                elif src[j] == "\n" and c != "`":
                    break
                j += 1
            out.append(c + c + "\n" * src.count("\n", i, min(j + 1, n)))
            i = j + 1
            continue
        out.append(c)
        i += 1
    return "".join(out)


QUALIFIERS = re.compile(r"(\s*(const|noexcept(\([^()]*\))?|override|final|mutable|volatile|&&|&|"
                        r"->\s*[\w:<>,\s*&]+))*\s*$")


def opens_function(before):
    """Whether the text before a `{` at namespace or class level ends with a function's signature;
    returns its name or None."""
    text = QUALIFIERS.sub("", before)
    # A constructor's initialiser list: ") : a_(x), b_{y}" -- cut back to the ':' after the ')'.
    m = re.search(r"\)\s*:\s*[\w:]+\s*[({][^;]*$", text)
    if m and not text.rstrip().endswith(")"):
        text = text[:m.start() + 1]
    elif m:
        text = text[:m.start() + 1]
    text = text.rstrip()
    if not text.endswith(")"):
        return None
    depth, j = 0, len(text) - 1
    while j >= 0:
        if text[j] == ")":
            depth += 1
        elif text[j] == "(":
            depth -= 1
            if depth == 0:
                break
        j -= 1
    m = re.search(r"(operator\s*\S+?|[~\w:]+)\s*$", text[:j])
    if not m or m.group(1) in NOT_CALLS:
        return None
    return m.group(1)


def brace_functions(path):
    """(length, first line, name) of every function in a C++ or JavaScript file."""
    with open(path, encoding="utf-8", errors="replace") as f:
        s = blank_comments_and_strings(f.read())
    found, stack, line, last = [], [], 1, 0
    for i, c in enumerate(s):
        if c == "\n":
            line += 1
        elif c == "{":
            name = None
            if not any(kind == "function" for kind, _, _ in stack):
                name = opens_function(s[max(0, i - 2000):i])
            stack.append(("function" if name else "block", line, name))
        elif c == "}" and stack:
            kind, start, name = stack.pop()
            if kind == "function":
                found.append((line - start + 1, start, name))
    return found


def python_functions(path):
    with open(path, encoding="utf-8") as f:
        tree = ast.parse(f.read(), path)
    found = []

    def visit(node, inside):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if not inside:  # a nested def counts towards its outer function
                    found.append((child.end_lineno - child.lineno + 1, child.lineno, child.name))
                visit(child, True)
            else:
                visit(child, inside)

    visit(tree, False)
    return found


def all_functions(root):
    for top in SOURCE_DIRS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(root, top)):
            dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS)
            for name in sorted(filenames):
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, root)
                if name.endswith((".cpp", ".hpp", ".h", ".c", ".js")):
                    found = brace_functions(path)
                elif name.endswith(".py"):
                    found = python_functions(path)
                else:
                    continue
                for length, start, fname in found:
                    yield length, rel, start, fname


def read_allowed(path):
    allowed = {}
    if not path:
        return allowed
    with open(path, encoding="utf-8") as f:
        for k, raw in enumerate(f, 1):
            text = raw.split("#", 1)[0].strip()
            if not text:
                continue
            parts = text.split()
            if len(parts) != 3 or not parts[0].isdigit():
                sys.exit(f"{path}:{k}: expected 'LENGTH PATH NAME', got {raw.strip()!r}")
            allowed[(parts[1], parts[2])] = int(parts[0])
    return allowed


def self_test():
    """The counting on written cases of known length; returns the failures."""
    import tempfile
    body = "\n".join(f"  x += {k};" for k in range(10))
    cases = {
        # (source, extension): [(length, name)] expected
        ("int f(int x) {\n" + body + "\n  return x;\n}\n", ".cpp"): [(13, "f")],
        # braces in strings, raw strings, comments and character literals do not count; a lambda and a
        # local struct count towards their function; a constructor's initialiser list; qualifiers
        ('struct A {\n  A(int v) : v_{v}, w_(v) {\n    const char* s = "}{";\n  }\n'
         '  int get() const noexcept { return v_; }\n  int v_, w_;\n};\n'
         'auto g() -> int {\n  auto l = [](int y) {\n    return y; // }\n  };\n'
         '  const char* r = R"x(}})x";\n  char c = \'}\';\n  struct L { int m() { return 1; } };\n'
         '  /* } */\n  return l(1);\n}\nnamespace n {\nvoid h() noexcept {}\n}  // namespace n\n', ".cpp"):
            [(3, "A"), (1, "get"), (10, "g"), (1, "h")],
        ("function draw(a) {\n  if (a) {\n    return `}`;\n  }\n  return a;\n}\n", ".js"): [(6, "draw")],
        ("def f(x):\n    def inner():\n        return 1\n    return inner()\n\n\nclass C:\n    def m(self):\n"
         "        pass\n", ".py"): [(4, "f"), (2, "m")],
    }
    failures = []
    with tempfile.TemporaryDirectory() as d:
        for (src, ext), want in cases.items():
            path = os.path.join(d, "case" + ext)
            with open(path, "w", encoding="utf-8") as f:
                f.write(src)
            found = python_functions(path) if ext == ".py" else brace_functions(path)
            got = sorted((length, name) for length, _, name in found)
            if got != sorted(want):
                failures.append(f"{ext} case: want {sorted(want)}, got {got}")
    return failures


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("root", nargs="?", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    ap.add_argument("--limit", type=int, default=120, help="longest allowed function, lines (120)")
    ap.add_argument("--allow", help="functions over the limit not yet split: 'LENGTH PATH NAME' per line")
    ap.add_argument("--top", type=int, default=0, help="also print the K longest functions")
    ap.add_argument("--self-test", action="store_true", help="check the counting on written cases first")
    args = ap.parse_args()
    if args.self_test:
        failures = self_test()
        for f in failures:
            print("self-test FAILED: " + f)
        if failures:
            return 1
        print("self-test: every written case counted right")
    root = os.path.abspath(args.root)
    funcs = sorted(all_functions(root), key=lambda f: (-f[0], f[1], f[2]))
    allowed = read_allowed(args.allow)
    if args.top:
        print(f"the {args.top} longest functions:")
        for length, rel, start, name in funcs[:args.top]:
            print(f"  {length:4d}  {rel}:{start}  {name}")
    failures = 0
    long_ones = [f for f in funcs if f[0] > args.limit]
    for length, rel, start, name in long_ones:
        cap = allowed.get((rel, name))
        if cap is None:
            verdict = "NEW: split it"
            failures += 1
        elif length > cap:
            verdict = f"GREW past {cap}"
            failures += 1
        else:
            verdict = "not split yet"
        print(f"{length:4d}  {rel}:{start}  {name}  ({verdict})")
    left = {k for k in allowed if not any((f[1], f[3]) == k and f[0] > args.limit for f in funcs)}
    for rel, name in sorted(left):
        print(f"note: {rel} {name} is no longer over {args.limit} lines: remove it from {args.allow}")
    print(f"{len(funcs)} functions, {len(long_ones)} over {args.limit} lines, {failures} not allowed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
