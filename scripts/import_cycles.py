#!/usr/bin/env python3
"""Prints the import cycles between the modules of one Rust crate; exits 1 if there are any.

    python3 scripts/import_cycles.py --crate-root stages/src

A module is a top-level file or folder under the crate root (`graph.rs`, `lift/`, or both
`place.rs` and `place/`), and, inside a folder module, each file or folder one level down
(`tasks/chat.rs`). Two graphs are checked: the top-level modules (a reference from any file
of `lift/` to `crate::graph` is the edge lift -> graph), and the submodules of each folder
(`tasks/scene.rs` naming `super::chat` is the edge tasks::chat -> tasks::scene's sibling). A
folder's own `mod.rs` (or `x.rs`) and its submodules are parent and children, not siblings:
the parent declares and re-exports its children, and children reach the parent's shared
types, so that pair is no edge.

References are `crate::`, `super::` and `self::` paths anywhere in the code (imports, types,
calls, macro bodies), and in a parent file the names of its own submodules (`scene::View`).
A name re-exported by `lib.rs` or a `mod.rs` (`pub use llm::LlmLayout`) resolves to the module
that defines it. Comments, string literals and `#[cfg(test)]` items (inline `mod tests { .. }`
blocks, `#[cfg(test)] mod tests;` files, `#[cfg(test)] use ..`) are ignored: a test may reach
anywhere.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections import defaultdict

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
RAW_STRING = re.compile(r'b?r(#*)"')
CHAR = re.compile(r"'(\\u\{[0-9a-fA-F]+\}|\\.|[^\\'])'")
ROOT_FILES = ("lib.rs", "main.rs")


def strip_comments_and_strings(text: str) -> str:
    """Blanks comments and string/char literals, keeping newlines (so line numbers hold)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif (m := RAW_STRING.match(text, i)) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            end = '"' + m.group(1)
            j = text.find(end, m.end())
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'":
            # A char literal ('a', '\n', '\u{1f}'), not a lifetime ('a).
            m = CHAR.match(text, i)
            if m:
                out.append(" " * (m.end() - i))
                i = m.end()
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(text: str, open_at: int) -> int:
    depth = 0
    for j in range(open_at, len(text)):
        if text[j] == "{":
            depth += 1
        elif text[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(text) - 1


def strip_test_items(text: str) -> tuple[str, set[str]]:
    """Blanks `#[cfg(test)]` items; returns the text and the names of `#[cfg(test)] mod x;`."""
    test_files = set()
    pattern = re.compile(r"#\[cfg\(test\)\]\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?")
    pos = 0
    while (m := pattern.search(text, pos)) is not None:
        rest = text[m.end():]
        if mod := re.match(rf"mod\s+({IDENT})\s*;", rest):
            test_files.add(mod.group(1))
            end = m.end() + mod.end()
        elif re.match(r"(mod|fn|impl)\b", rest):
            brace = text.find("{", m.end())
            end = matching_brace(text, brace) + 1
        elif re.match(r"use\b", rest):
            end = text.find(";", m.end()) + 1
        else:
            pos = m.end()
            continue
        text = text[: m.start()] + re.sub(r"[^\n]", " ", text[m.start():end]) + text[end:]
        pos = end
    return text, test_files


def use_trees(text: str):
    """Yields (line, path) for every leaf of every `use` tree, `{}` groups expanded."""
    for m in re.finditer(r"\buse\s+([^;]*);", text):
        line = text.count("\n", 0, m.start()) + 1
        tree = re.sub(r"\s+as\s+" + IDENT, "", m.group(1))
        for path in expand(re.sub(r"\s+", "", tree)):
            yield line, path


def expand(tree: str) -> list[list[str]]:
    """`a::{b,c::{d,e}}` -> [[a,b],[a,c,d],[a,c,e]] (`as` renames dropped)."""
    brace = tree.find("{")
    if brace < 0:
        return [[p for p in tree.split("::") if p]]
    prefix = [p for p in tree[:brace].split("::") if p]
    inner = tree[brace + 1 : tree.rfind("}")]
    parts, depth, start = [], 0, 0
    for j, ch in enumerate(inner):
        if ch == "{":
            depth += 1
        elif ch == "}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(inner[start:j])
            start = j + 1
    parts.append(inner[start:])
    return [prefix + sub for part in parts if part for sub in expand(part)]


class Crate:
    def __init__(self, root: str):
        self.root = root
        self.top: dict[str, list[str]] = {}  # module -> its files
        self.children: dict[str, set[str]] = defaultdict(set)  # folder module -> submodules
        self.files: dict[str, tuple[str, ...]] = {}  # file -> module path (1 or 2 names)
        for entry in sorted(os.listdir(root)):
            full = os.path.join(root, entry)
            if entry.endswith(".rs") and entry not in ROOT_FILES:
                name = entry[:-3]
                self.top.setdefault(name, []).append(full)
                self.files[full] = (name,)
            elif os.path.isdir(full):
                self.top.setdefault(entry, [])
                for dirpath, _, names in os.walk(full):
                    for file in sorted(names):
                        if not file.endswith(".rs"):
                            continue
                        path = os.path.join(dirpath, file)
                        rel = os.path.relpath(path, full).split(os.sep)
                        if rel == ["mod.rs"]:
                            self.files[path] = (entry,)
                        else:
                            child = rel[0][:-3] if len(rel) == 1 else rel[0]
                            self.children[entry].add(child)
                            self.files[path] = (entry, child)
                        self.top[entry].append(path)
        self.test_files: set[str] = set()
        self.texts: dict[str, str] = {}
        for path in list(self.files) + [os.path.join(root, f) for f in ROOT_FILES]:
            if not os.path.exists(path):
                continue
            with open(path, encoding="utf-8") as f:
                text, tests = strip_test_items(strip_comments_and_strings(f.read()))
            self.texts[path] = text
            folder = path[:-3] if not path.endswith("mod.rs") else os.path.dirname(path)
            if os.path.basename(path) in ROOT_FILES:
                folder = root
            for name in tests:
                self.test_files.add(os.path.join(folder, name + ".rs"))
                self.test_files.add(os.path.join(folder, name, "mod.rs"))
        # Re-exports: (module path of the re-exporting file, name) -> absolute path of the item.
        self.reexports: dict[tuple[tuple[str, ...], str], list[str]] = {}
        for path, text in self.texts.items():
            here = self.module_of(path)
            for m in re.finditer(r"\bpub(?:\([^)]*\))?\s+use\s+([^;]*);", text):
                tree = re.sub(r"\s+as\s+" + IDENT, "", m.group(1))
                for leaf in expand(re.sub(r"\s+", "", tree)):
                    absolute = self.absolute(here, leaf, is_parent=True)
                    if absolute and leaf:
                        self.reexports[(here, leaf[-1])] = absolute

    def module_of(self, path: str) -> tuple[str, ...]:
        return () if os.path.dirname(path) == self.root and os.path.basename(path) in ROOT_FILES else self.files[path]

    def absolute(self, here: tuple[str, ...], path: list[str], is_parent: bool) -> list[str] | None:
        """The crate-absolute form of a path seen in module `here`, or None if outside."""
        if not path:
            return None
        head = path[0]
        if head == "crate":
            return path[1:]
        if head in ("self", "super"):
            base = list(here)
            rest = path
            while rest and rest[0] in ("self", "super"):
                if rest[0] == "super":
                    if not base:
                        return None
                    base = base[:-1]
                rest = rest[1:]
            return base + rest
        # A bare first segment: a submodule of this (parent or root) file.
        if is_parent:
            if not here and head in self.top:
                return path
            if len(here) == 1 and head in self.children.get(here[0], ()):
                return [here[0]] + path
        return None

    def resolve(self, absolute: list[str]) -> tuple[str, ...] | None:
        """The module (one or two names) an absolute path lands in, following re-exports."""
        for _ in range(8):
            if not absolute:
                return None
            top = absolute[0]
            if top not in self.top:
                target = self.reexports.get(((), top))
                if target is None:
                    return None
                absolute = target + absolute[1:]
                continue
            if len(absolute) > 1 and absolute[1] in self.children.get(top, ()):
                return (top, absolute[1])
            if len(absolute) > 1 and ((top,), absolute[1]) in self.reexports:
                target = self.reexports[((top,), absolute[1])]
                if target[:1] == [top]:
                    absolute = target + absolute[2:]
                    continue
            return (top,)
        return None

    def references(self):
        """Yields (from module, to module, file, line) for every reference between modules."""
        for path, text in self.texts.items():
            if path in self.test_files:
                continue
            here = self.module_of(path)
            if not here:
                continue
            is_parent = len(here) == 1
            found = []
            for line, leaf in use_trees(text):
                found.append((line, leaf))
            starts = [r"crate", r"super", r"self"]
            if is_parent:
                starts += [re.escape(c) for c in self.children.get(here[0], ())]
            pattern = re.compile(rf"(?<![\w:])((?:{'|'.join(starts)})(?:::{IDENT})+)")
            for m in pattern.finditer(text):
                found.append((text.count("\n", 0, m.start()) + 1, m.group(1).split("::")))
            for line, leaf in found:
                absolute = self.absolute(here, leaf, is_parent)
                target = self.resolve(absolute) if absolute is not None else None
                if target is None or target == here:
                    continue
                yield here, target, path, line


def cycles(edges: dict[str, dict[str, tuple[str, int]]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, {})):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return sorted(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--crate-root", required=True, help="the crate's src/ folder")
    parser.add_argument("--edges", action="store_true", help="also print every edge found")
    args = parser.parse_args()
    crate = Crate(os.path.normpath(args.crate_root))
    graphs: dict[str, dict[str, dict[str, tuple[str, int]]]] = defaultdict(lambda: defaultdict(dict))
    for source, target, path, line in crate.references():
        where = (os.path.relpath(path, crate.root), line)
        if source[0] != target[0]:
            graphs[""][source[0]].setdefault(target[0], where)
        elif len(source) == 2 and len(target) == 2:
            graphs[source[0]][source[1]].setdefault(target[1], where)
    if args.edges:
        for scope in sorted(graphs):
            for a in sorted(graphs[scope]):
                for b, (file, line) in sorted(graphs[scope][a].items()):
                    prefix = f"{scope}::" if scope else ""
                    print(f"edge: {prefix}{a} -> {prefix}{b}  ({file}:{line})")
    found = 0
    for scope in sorted(graphs):
        edges = graphs[scope]
        for component in cycles(edges):
            found += 1
            name = (lambda m: f"{scope}::{m}") if scope else (lambda m: m)
            print(f"cycle: {', '.join(name(m) for m in component)}")
            members = set(component)
            for a in component:
                for b, (file, line) in sorted(edges[a].items()):
                    if b in members:
                        print(f"  {name(a)} -> {name(b)}  ({file}:{line})")
    if found:
        print(f"{found} cycle(s) in {args.crate_root}")
        return 1
    print(f"no cycles in {args.crate_root}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
