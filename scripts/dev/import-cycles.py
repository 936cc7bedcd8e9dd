#!/usr/bin/env python3
"""Lists the import cycles between the files of each crate: which file's `use` (and
`crate::`/`super::`/`self::` paths) names an item of which other file, and every strongly
connected group of files that import each other, directly or around a circle. Also lists
child files that import an item their parent `mod.rs` (or `lib.rs`) defines itself, as
opposed to one it re-exports: a face declares modules and re-exports, and defines at most
constants.

    python3 scripts/dev/import-cycles.py [CRATE_SRC ...]   (default: every crate's src/)

Exits 1 if any cycle, or any import of an item a parent's face defines, is found. A path is resolved to the longest module prefix that is a
file of the crate (`crate::bft::chunked::sort::X` -> `bft/chunked/sort.rs`); an item of a
module's face (`mod.rs`) counts as that face's.
"""
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")


def modules(src):
    """module path (tuple) -> file"""
    out = {}
    for dirpath, _, files in os.walk(src):
        for f in files:
            if not f.endswith(".rs"):
                continue
            rel = os.path.relpath(os.path.join(dirpath, f), src)
            parts = rel[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib", "main"):
                parts = parts[:-1]
            out[tuple(parts)] = os.path.join(dirpath, f)
    return out


def strip_comments(text):
    text = re.sub(r"//[^\n]*", "", text)
    return re.sub(r"/\*.*?\*/", "", text, flags=re.S)


def test_free(text):
    """The file without its `#[cfg(test)] mod ... { }` blocks (tests may import anything)."""
    out, i = [], 0
    for m in re.finditer(r"#\[cfg\(test\)\]\s*mod\s+\w+\s*\{", text):
        if m.start() < i:
            continue
        out.append(text[i:m.start()])
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[j], 0)
            j += 1
        i = j
    out.append(text[i:])
    return "".join(out)


def paths_in(text):
    """Every `use` tree expanded, and every inline crate::/super::/self:: path."""
    found = []

    def expand(prefix, tree):
        tree = tree.strip()
        m = re.match(r"^(.*?)::\{(.*)\}$", tree, re.S)
        if m:
            head = prefix + [p for p in m.group(1).split("::") if p]
            depth, cur, items = 0, "", []
            for ch in m.group(2):
                if ch == "{":
                    depth += 1
                elif ch == "}":
                    depth -= 1
                if ch == "," and depth == 0:
                    items.append(cur)
                    cur = ""
                else:
                    cur += ch
            items.append(cur)
            for it in items:
                if it.strip():
                    expand(head, it)
        elif tree.startswith("{") and tree.endswith("}"):
            expand(prefix, "x::" + tree)  # a bare group
        else:
            name = re.split(r"\s+as\s+", tree)[0]
            found.append(prefix + [p for p in name.split("::") if p])

    for m in re.finditer(r"\buse\s+([^;]+);", text):
        expand([], m.group(1))
    for m in re.finditer(r"\b((?:crate|super|self)(?:::\w+)+)", text):
        found.append(m.group(1).split("::"))
    return found


def resolve(path, here, mods):
    """The module a path's item lives in, or None if outside the crate."""
    if not path:
        return None
    if path[0] == "crate":
        base = []
    elif path[0] in ("super", "self"):
        base = list(here)
        while path and path[0] in ("super", "self"):
            if path[0] == "super":
                base = base[:-1]
            path = path[1:]
        path = ["_"] + path
    else:
        return None
    rest = path[1:]
    for k in range(len(rest), -1, -1):
        cand = tuple(base + rest[:k])
        if cand in mods:
            return cand
    return None


DEFINED = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:struct|enum|trait|fn|type|static|union|macro_rules!)\s+(\w+)", re.M)


def defined_in(text):
    """The names of the structs, enums, traits, functions, types and statics a file defines
    at its top level (constants are allowed in a face)."""
    return {m.group(1) for m in DEFINED.finditer(text) if not m.group(0).startswith((" ", "\t"))}


def scc(graph):
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    return out


def main():
    # Every crate of the workspace, the codec's nested ones (codec/*/) included.
    crates = [d for d in os.listdir(ROOT) if os.path.isfile(os.path.join(ROOT, d, "Cargo.toml"))]
    crates += [os.path.join("codec", d) for d in os.listdir(os.path.join(ROOT, "codec"))]
    srcs = sys.argv[1:] or sorted(
        os.path.join(ROOT, d, "src")
        for d in crates
        if os.path.isfile(os.path.join(ROOT, d, "Cargo.toml")) and os.path.isdir(os.path.join(ROOT, d, "src"))
    )
    cycles, face_imports = 0, 0
    for src in srcs:
        mods = modules(src)
        graph, parent_imports = {}, []
        defs = {mod: defined_in(test_free(strip_comments(open(f).read()))) for mod, f in mods.items()}
        for mod, f in mods.items():
            text = test_free(strip_comments(open(f).read()))
            for p in paths_in(text):
                target = resolve(p, mod, mods)
                if target is None or target == mod:
                    continue
                # A module declaring its children is the face, not an import.
                if len(target) == len(mod) + 1 and target[:-1] == mod and len(p) <= 2:
                    continue
                graph.setdefault(mod, set()).add(target)
                if len(mod) >= 1 and target == mod[:-1] and p[-1] in defs[target]:
                    parent_imports.append((mod, p[-1]))
        name = os.path.relpath(src, ROOT)
        comps = scc(graph)
        for comp in comps:
            cycles += 1
            files = sorted("/".join(c) or "lib" for c in comp)
            print(f"{name}: cycle among {', '.join(files)}")
        for mod, item in sorted(set(parent_imports)):
            face_imports += 1
            print(f"{name}: {'/'.join(mod)} imports {item}, which its parent's face defines")
    print(f"{cycles} import cycles, {face_imports} imports of an item a face defines")
    sys.exit(1 if cycles or face_imports else 0)


if __name__ == "__main__":
    main()
