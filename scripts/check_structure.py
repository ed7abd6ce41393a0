#!/usr/bin/env python3
"""Checks the shape of the source tree (docs/architecture.md, "Rules of the tree"):

1. No import loop: in each crate, the graph of modules (one node per file) with an edge for
   every `use` or path that names another module of the same crate has no cycle. A name that a
   module only re-exports (`pub use child::Name`) counts as an edge to the module that defines
   it, so `gpu/mod.rs` re-exporting its children is no loop. A module may use what its own
   ancestors define (a folder's `mod.rs` or the crate root is the interface its children share,
   as Rust lays modules out), so edges from a module up to an ancestor are not counted; every
   other edge is, between siblings and cousins alike. `#[cfg(test)]` modules are left out.
2. No Rust or WGSL source file above 1,000 lines.

Usage: `python3 scripts/check_structure.py [ROOT]` prints each problem and exits 1 if any;
`--self-test` checks the checker on small trees it writes (a loop, a re-export, a long file).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

MAX_LINES = 1000
SKIP_DIRS = {"target", "node_modules", ".venv", ".git", ".node", "dist"}

MOD_DECL = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;", re.M)
DEFINITION = re.compile(
    r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:(?:unsafe|async|const|extern\s+\"C\")\s+)*"
    r"(?:struct|enum|fn|trait|type|const|static|union|macro_rules!)\s+(\w+)",
    re.M,
)
MACRO_EXPORT = re.compile(r"macro_rules!\s+(\w+)")
USE_STMT = re.compile(r"^\s*(pub(?:\([^)]*\))?\s+)?use\s+([^;]+);", re.M)
INLINE_PATH = re.compile(r"(?<![\w:])(crate|super|self)((?:::\w+)+)")


def strip_comments_and_strings(text: str) -> str:
    """Blanks out comments and string literals (keeping line breaks, so line numbers hold)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
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
            out.append("\n" * text.count("\n", i, j))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:i + 8]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            hashes = re.match(r'r(#*)"', text[i:]).group(1)
            end = text.find('"' + hashes, i + 2 + len(hashes))
            end = n if end < 0 else end + 1 + len(hashes)
            out.append('""' + "\n" * text.count("\n", i, end))
            i = end
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append('""' + "\n" * text.count("\n", i, j))
            i = j + 1
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i:i + 4]) or text.startswith("'\\u{", i):
            j = text.find("'", i + 1 if text[i + 1] != "\\" else i + 2)
            out.append("' '")
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def drop_test_modules(text: str) -> str:
    """Blanks `#[cfg(test)] mod name { ... }` blocks (keeping line breaks)."""
    while True:
        m = re.search(r"#\[cfg\(test\)\]\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{", text)
        if not m:
            return text
        depth, j = 1, m.end()
        while j < len(text) and depth:
            depth += {"{": 1, "}": -1}.get(text[j], 0)
            j += 1
        text = text[: m.start()] + "\n" * text.count("\n", m.start(), j) + text[j:]


def expand_use_tree(tree: str) -> list[tuple[list[str], str | None]]:
    """`a::{b, c::{d as e}, f::*}` -> [(['a','b'], None), (['a','c','d'], 'e'), (['a','f','*'], None)]."""
    tree = re.sub(r"\s+", "", tree)

    def parse(s: str, prefix: list[str]) -> list[tuple[list[str], str | None]]:
        items, depth, start = [], 0, 0
        for k, ch in enumerate(s):
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
            elif ch == "," and depth == 0:
                items.append(s[start:k])
                start = k + 1
        items.append(s[start:])
        result = []
        for item in filter(None, items):
            if "{" in item:
                head, rest = item.split("{", 1)
                head_parts = [p for p in head.split("::") if p]
                result += parse(rest[:-1], prefix + head_parts)
            else:
                alias = None
                if "as" in item and re.search(r"[a-zA-Z0-9_*]as[a-zA-Z_]", item):
                    item, alias = re.split(r"(?<=[\w*])as(?=[A-Za-z_])", item, maxsplit=1)
                parts = [p for p in item.split("::") if p]
                if parts == ["self"]:
                    parts = []
                result.append((prefix + parts, alias))
        return result

    return parse(tree, [])


class Crate:
    """The modules of one crate root (lib.rs or main.rs), found by following `mod x;`."""

    def __init__(self, root_file: Path):
        self.root_file = root_file
        self.files: dict[tuple[str, ...], Path] = {}
        self.text: dict[tuple[str, ...], str] = {}
        self._collect((), root_file)
        self.defined = {m: set(DEFINITION.findall(t)) | set(MACRO_EXPORT.findall(t)) for m, t in self.text.items()}
        self.reexports: dict[tuple[str, ...], dict[str, list[str]]] = {}
        self.globs: dict[tuple[str, ...], list[list[str]]] = {}
        for m, t in self.text.items():
            named, globs = {}, []
            for vis, tree in USE_STMT.findall(t):
                if not vis:
                    continue
                for path, alias in expand_use_tree(tree):
                    if not path:
                        continue
                    abs_path = self.absolute(m, path)
                    if abs_path is None:
                        continue
                    if path[-1] == "*":
                        globs.append(abs_path[:-1])
                    else:
                        named[alias or path[-1]] = abs_path
            self.reexports[m], self.globs[m] = named, globs

    def _collect(self, module: tuple[str, ...], path: Path) -> None:
        raw = path.read_text(encoding="utf-8")
        text = drop_test_modules(strip_comments_and_strings(raw))
        self.files[module], self.text[module] = path, text
        if path.name in ("lib.rs", "main.rs", "mod.rs"):
            base = path.parent
        else:
            base = path.parent / path.stem
        for name in MOD_DECL.findall(text):
            for candidate in (base / f"{name}.rs", base / name / "mod.rs"):
                if candidate.exists():
                    self._collect(module + (name,), candidate)
                    break

    def absolute(self, current: tuple[str, ...], path: list[str]) -> list[str] | None:
        """A path as written in `current` -> segments from the crate root, or None if external."""
        if path[0] == "crate":
            return path[1:]
        if path[0] in ("super", "self"):
            base = list(current)
            rest = list(path)
            while rest and rest[0] in ("super", "self"):
                if rest.pop(0) == "super":
                    if not base:
                        return None
                    base.pop()
            return base + rest
        if tuple(current) + (path[0],) in self.files:
            return list(current) + path
        return None

    def resolve(self, segments: list[str], depth: int = 0) -> tuple[str, ...] | None:
        """The module that defines what `segments` (from the root) names."""
        module: tuple[str, ...] = ()
        i = 0
        while i < len(segments) and module + (segments[i],) in self.files:
            module += (segments[i],)
            i += 1
        if i == len(segments) or segments[i] == "*" or depth > 16:
            return module
        name = segments[i]
        if name in self.defined.get(module, ()):
            return module
        target = self.reexports.get(module, {}).get(name)
        if target is not None:
            return self.resolve(target + segments[i + 1:], depth + 1)
        for glob in self.globs.get(module, []):
            found = self.resolve(glob + [name], depth + 1)
            if found is not None and name in self.defined.get(found, ()):
                return found
        return module

    def edges(self) -> dict[tuple[str, ...], dict[tuple[str, ...], int]]:
        """module -> {module it names: first line that names it}."""
        graph: dict[tuple[str, ...], dict[tuple[str, ...], int]] = {m: {} for m in self.files}
        for m, text in self.text.items():
            found: list[tuple[list[str], int]] = []
            for stmt in USE_STMT.finditer(text):
                line = text.count("\n", 0, stmt.start()) + 1
                for path, _ in expand_use_tree(stmt.group(2)):
                    if path:
                        found.append((path, line))
            for ref in INLINE_PATH.finditer(text):
                if text[: ref.start()].rstrip().endswith("use"):
                    continue
                path = [ref.group(1)] + ref.group(2).strip(":").split("::")
                found.append((path, text.count("\n", 0, ref.start()) + 1))
            for path, line in found:
                segments = self.absolute(m, path)
                if segments is None:
                    continue
                target = self.resolve(segments)
                ancestor = target is not None and m[: len(target)] == target
                if target is not None and not ancestor and target not in graph[m]:
                    graph[m][target] = line
        return graph


def cycles(graph: dict) -> list[list]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, result = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                result.append(sorted(component))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return result


def folder_graph(graph: dict) -> dict:
    """The edges between sibling subtrees: an edge from `a::x::f` to `b::y` becomes one from
    the folder `a` to the folder `b` (the children of their deepest common ancestor), with the
    file edge that gave it. A loop here and none among files is a loop between folders."""
    folders: dict = {}
    for u, targets in graph.items():
        for v, line in targets.items():
            k = 0
            while k < min(len(u), len(v)) and u[k] == v[k]:
                k += 1
            if k < len(u) and k < len(v):
                a, b = u[: k + 1], v[: k + 1]
                folders.setdefault(b, {})
                folders.setdefault(a, {}).setdefault(b, (u, line))
    return folders


def crate_roots(root: Path) -> list[Path]:
    """Every `src/lib.rs` and `src/main.rs` below `root`, outside build and tool folders."""
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not d.startswith("."))
        if Path(dirpath).name == "src":
            for name in ("lib.rs", "main.rs"):
                if name in filenames:
                    found.append(Path(dirpath) / name)
    return found


def long_files(root: Path) -> list[str]:
    """Rust and WGSL files above MAX_LINES lines."""
    problems = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in SKIP_DIRS and not d.startswith("."))
        for name in sorted(filenames):
            if name.endswith((".rs", ".wgsl")):
                path = Path(dirpath) / name
                lines = path.read_text(encoding="utf-8", errors="replace").count("\n")
                if lines > MAX_LINES:
                    problems.append(f"{path.relative_to(root)}: {lines} lines (at most {MAX_LINES}): split it by concept")
    return problems


def loop_problems(root: Path) -> list[str]:
    """One message per import loop, naming its modules and one line of each edge inside it."""
    problems = []
    for root_file in crate_roots(root):
        crate = Crate(root_file)
        graph = crate.edges()
        for component in cycles(graph):
            members = set(component)
            lines = []
            for m in component:
                for target, line in sorted(graph[m].items()):
                    if target in members:
                        src = crate.files[m].relative_to(root)
                        lines.append(f"    {src}:{line} uses {'::'.join(('crate',) + target)}")
            names = ", ".join("::".join(("crate",) + m) for m in component)
            problems.append(f"{root_file.relative_to(root)}: import loop between {names}\n" + "\n".join(lines))
        if problems:
            continue
        folders = folder_graph(graph)
        for component in cycles(folders):
            members = set(component)
            lines = []
            for m in component:
                for target, (file, line) in sorted(folders[m].items()):
                    if target in members:
                        src = crate.files[file].relative_to(root)
                        lines.append(f"    {src}:{line} uses {'::'.join(('crate',) + target)}")
            names = ", ".join("::".join(("crate",) + m) for m in component)
            problems.append(f"{root_file.relative_to(root)}: import loop between folders {names}\n" + "\n".join(lines))
    return problems


def self_test() -> None:
    """The checker finds a loop, follows re-exports, and flags a long file; the trees it writes
    are removed afterwards, whatever happens."""
    with tempfile.TemporaryDirectory(prefix="check-structure-") as scratch:
        self_test_in(Path(scratch))


def self_test_in(scratch: Path) -> None:
    """`self_test`, its trees written under `scratch`."""

    def tree(files: dict[str, str]) -> Path:
        d = Path(tempfile.mkdtemp(dir=scratch))
        for name, text in files.items():
            (d / name).parent.mkdir(parents=True, exist_ok=True)
            (d / name).write_text(text)
        return d

    looped = tree({
        "k/src/lib.rs": "mod a;\nmod b;\n",
        "k/src/a.rs": "use crate::b::B;\npub struct A;\n",
        "k/src/b.rs": "pub struct B;\nfn f() { let _ = super::a::A; }\n",
    })
    found = loop_problems(looped)
    assert len(found) == 1 and "import loop between crate::a, crate::b" in found[0], found
    assert "k/src/a.rs:1 uses crate::b" in found[0] and "k/src/b.rs:2 uses crate::a" in found[0], found

    reexported = tree({
        "k/src/lib.rs": "pub mod gpu;\n",
        "k/src/gpu/mod.rs": "mod method;\nmod probe;\npub use method::Method;\npub use probe::Probe;\n",
        "k/src/gpu/method.rs": "/// m\npub enum Method { A }\n",
        "k/src/gpu/probe.rs": "use crate::gpu::Method;\n// use crate::gpu::probe;\npub struct Probe(Method);\n"
        "#[cfg(test)]\nmod tests {\n    use crate::gpu::*;\n}\n",
    })
    assert loop_problems(reexported) == [], loop_problems(reexported)

    defined_in_parent = tree({
        "k/src/lib.rs": "pub mod gpu;\n",
        "k/src/gpu/mod.rs": "mod probe;\nmod tables;\npub use probe::Probe;\npub enum Method { A }\n",
        "k/src/gpu/probe.rs": "use super::{Method, self as up};\npub struct Probe(Method);\n",
        "k/src/gpu/tables.rs": "use super::Method;\nfn f() -> crate::gpu::Probe { todo!() }\n",
    })
    assert loop_problems(defined_in_parent) == [], loop_problems(defined_in_parent)
    cousins = tree({
        "k/src/lib.rs": "mod a;\nmod b;\n",
        "k/src/a/mod.rs": "mod x;\n",
        "k/src/a/x.rs": "use crate::b::y::Y;\npub struct X;\n",
        "k/src/b/mod.rs": "pub mod y;\n",
        "k/src/b/y.rs": "pub struct Y(crate::a::x::X);\n",
    })
    found = loop_problems(cousins)
    assert len(found) == 1 and "crate::a::x, crate::b::y" in found[0], found

    folders = tree({
        "k/src/lib.rs": "mod convert;\nmod partition;\n",
        "k/src/convert/mod.rs": "mod pass;\n",
        "k/src/convert/pass.rs": "use crate::partition::plan::Plan;\n",
        "k/src/partition/mod.rs": "mod plan;\nmod run;\n",
        "k/src/partition/plan.rs": "pub struct Plan;\n",
        "k/src/partition/run.rs": "use crate::convert::pass;\n",
    })
    found = loop_problems(folders)
    assert len(found) == 1 and "import loop between folders crate::convert, crate::partition" in found[0], found
    assert "k/src/partition/run.rs:1 uses crate::convert" in found[0], found

    long = tree({"k/src/lib.rs": "//\n" * (MAX_LINES + 1), "s/x.wgsl": "\n" * MAX_LINES})
    assert long_files(long) == [f"k/src/lib.rs: {MAX_LINES + 1} lines (at most {MAX_LINES}): split it by concept"], long_files(long)
    print("check_structure self-test: 6 passed, 0 failed")


def main() -> int:
    if sys.argv[1:] == ["--self-test"]:
        self_test()
        return 0
    root = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent)
    problems = loop_problems(root) + long_files(root)
    for p in problems:
        print(p)
    if problems:
        print(f"check_structure: {len(problems)} problem(s)", file=sys.stderr)
        return 1
    print(f"check_structure: no import loop in {len(crate_roots(root))} crate roots, no source file above {MAX_LINES} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
