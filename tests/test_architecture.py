"""The layout the code promises (docs/architecture.md), checked rather than promised.

* the import-linter contracts of pyproject.toml (layers, independence of the two halves, the
  command line imported by nothing below it, the measurement chain by stage, the FMUs'
  packages free of numpy);
* no import cycle among modules, nor among the (sub)packages of a package;
* argparse only in the command-line package;
* no module over 450 lines and no function over 100 lines outside tests and benchmarks.

Independent truth for the cycles: the import graph is rebuilt here from the source with the
standard library's ``ast`` (every import statement, also those inside functions and
``TYPE_CHECKING`` blocks), not taken from import-linter.
"""
from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("abu", "abu_model", "controller", "fmus", "harness", "measurement", "twin")
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 100


def _modules() -> dict[str, tuple[Path, bool]]:
    mods = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            mods[".".join(parts)] = (f, is_pkg)
    return mods


def _import_graph() -> dict[str, set[str]]:
    mods = _modules()

    def owner(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = defaultdict(set)
    for mod, (path, is_pkg) in mods.items():
        base = mod if is_pkg else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    parts = base.split(".")[:len(base.split(".")) - (node.level - 1)]
                    src = ".".join(parts + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in mods else src
                           for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                if t.split(".")[0] in PACKAGES:
                    o = owner(t)
                    if o and o != mod:
                        edges[mod].add(o)
    return edges


def _cycles(nodes, edges) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    sys.setrecursionlimit(10000)

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
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
                out.append(sorted(comp))

    for v in nodes:
        if v not in index:
            visit(v)
    return out


def test_import_linter_contracts_are_kept():
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    assert exe, "import-linter is a test dependency (pip install -e '.[test]')"
    proc = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    print(proc.stdout[-2000:])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout and "6 kept" in proc.stdout


def test_no_module_cycle():
    edges = _import_graph()
    assert _cycles(list(_modules()), edges) == []


def test_no_package_cycle():
    mods = _modules()
    edges = _import_graph()

    def package(m: str) -> str:
        return m if mods[m][1] else m.rpartition(".")[0]

    pkg_edges: dict[str, set[str]] = defaultdict(set)
    for a, targets in edges.items():
        for b in targets:
            pa, pb = package(a), package(b)
            # a package's own modules may use its subpackages (a pipeline over its stages)
            if pa != pb and not pb.startswith(pa + ".") and not pa.startswith(pb + "."):
                pkg_edges[pa].add(pb)
    assert _cycles(sorted({package(m) for m in mods}), pkg_edges) == []


def test_the_cycle_finder_finds_a_cycle():
    # the finder itself, on a graph with one cycle a -> b -> c -> a and a tail d -> a
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(["a", "b", "c", "d"], edges) == [["a", "b", "c"]]


def test_argparse_only_in_the_command_line_package():
    users = []
    for mod, (path, _) in _modules().items():
        if mod == "abu.cli" or mod.startswith("abu.cli."):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module] if isinstance(node, ast.ImportFrom) else [])
            if "argparse" in names:
                users.append(mod)
    assert users == []


def test_modules_and_functions_stay_small():
    big = []
    for mod, (path, _) in _modules().items():
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > MAX_MODULE_LINES:
            big.append(f"module {mod}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    big.append(f"function {mod}.{node.name}: {n} lines")
    assert big == []
