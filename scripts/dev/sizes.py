#!/usr/bin/env python3
"""The size tables of the Rust sources: files and lines per crate, the largest files, and
the functions longer than a limit (their bodies found by brace matching outside strings and
comments, so the count is close, not exact).

    python3 scripts/dev/sizes.py [ROOT] [--over LINES]     (default: this checkout, 150)

Run it on another commit's tree with `git worktree add /tmp/x REV` and ROOT=/tmp/x.
"""
import os
import re
import sys

argv = sys.argv[1:]
over = 150
if "--over" in argv:
    k = argv.index("--over")
    over = int(argv[k + 1])
    del argv[k : k + 2]
root = os.path.abspath(argv[0] if argv else os.path.join(os.path.dirname(__file__), "..", ".."))


def rust_files():
    for dirpath, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in ("target", ".git", "fuzz", "node_modules")]
        for f in files:
            if f.endswith(".rs"):
                yield os.path.join(dirpath, f)


def crate_of(path):
    rel = os.path.relpath(path, root).split(os.sep)
    # codec/<crate>/src/... is a crate of its own; everything else is named by its top folder.
    if rel[0] == "codec" and len(rel) > 2 and rel[1] not in ("src", "tests", "examples", "benches"):
        return "codec/" + rel[1]
    return rel[0]


def blank_strings_and_comments(text):
    """The text with comments, strings and char literals blanked (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            hashes = re.match(r"r(#*)\"", text[i:]).group(1)
            j = text.find('"' + hashes, i + 2 + len(hashes))
            j = n if j < 0 else j + 1 + len(hashes)
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j + 1
        elif c == "'" and re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^'\\])'", text[i:]):
            m = re.match(r"'(\\.|\\u\{[0-9a-fA-F]+\}|[^'\\])'", text[i:])
            out.append("' '")
            i += m.end()
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(text):
    """(name, lines) of every fn with a body."""
    clean = blank_strings_and_comments(text)
    out = []
    for m in re.finditer(r"\bfn\s+(\w+)[^;{]*\{", clean):
        depth, j = 1, m.end()
        while j < len(clean) and depth:
            depth += {"{": 1, "}": -1}.get(clean[j], 0)
            j += 1
        out.append((m.group(1), clean.count("\n", m.start(), j) + 1))
    return out


per_crate, files, long = {}, [], []
for path in rust_files():
    text = open(path, encoding="utf-8", errors="replace").read()
    n = text.count("\n")
    crate = crate_of(path)
    c = per_crate.setdefault(crate, [0, 0])
    c[0] += 1
    c[1] += n
    rel = os.path.relpath(path, root)
    files.append((n, rel))
    long += [(lines, f"{rel}: {name}") for name, lines in functions(text) if lines > over]

print("| crate | files | lines |\n|---|---|---|")
for crate, (f, n) in sorted(per_crate.items()):
    print(f"| {crate} | {f} | {n:,} |")
print(f"| all | {sum(c[0] for c in per_crate.values())} | {sum(c[1] for c in per_crate.values()):,} |\n")
print("| largest files | lines |\n|---|---|")
for n, rel in sorted(files, reverse=True)[:10]:
    print(f"| {rel} | {n:,} |")
print(f"\n{len(long)} functions over {over} lines:")
for lines, what in sorted(long, reverse=True):
    print(f"  {lines:5}  {what}")
