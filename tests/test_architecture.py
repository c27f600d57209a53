"""The structure docs/architecture.md describes, kept true: the import-linter contracts in
pyproject.toml (the layers, no import circle, the NumPy reference out of the runtime path, the
config opening no recording) hold, and each source kind named in names.READERS has its reader."""

import importlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold():
    from importlinter.cli import lint_imports

    here = os.getcwd()
    os.chdir(ROOT)
    try:
        assert lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True) == 0, \
            "an import breaks a contract in pyproject.toml (run lint-imports to see which)"
    finally:
        os.chdir(here)


def test_a_contract_is_checked_not_assumed(tmp_path):
    """The linter fails a config whose layers are upside down (the check can fail)."""
    from importlinter.cli import lint_imports

    config = tmp_path / "upside_down.toml"
    config.write_text('[tool.importlinter]\nroot_package = "dpom_warp"\n\n[[tool.importlinter.contracts]]\n'
                      'name = "inverted"\ntype = "layers"\ncontainers = ["dpom_warp"]\n'
                      'layers = ["geometry", "cli"]\n')
    assert lint_imports(config_filename=str(config), no_cache=True) == 1


def test_every_source_kind_has_its_reader():
    from dpom_warp.names import READERS

    for kind, (_, module, name) in READERS.items():
        assert hasattr(importlib.import_module(f"dpom_warp.sources.{module}"), name), kind


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
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

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle_through_any_module_the_package_included():
    """Module by module, the package's own __init__ included (its lazy `Detector`): no circle.
    The one import taken out is `from . import kernels` (kernels/ is installed as
    dpom_warp.kernels, which the graph, built from dpom_warp/'s files, sees as the package)."""
    import grimp

    graph = grimp.build_graph("dpom_warp")
    edges = {}
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            details = graph.get_import_details(importer=module, imported=imported)
            if imported == "dpom_warp" and all("import kernels" in d["line_contents"] for d in details):
                continue
            edges.setdefault(module, set()).add(imported)
    assert _cycles(edges) == []
    edges.setdefault("dpom_warp.geometry", set()).add("dpom_warp.cli")  # the check can fail
    assert _cycles(edges)


def test_files_and_functions_stay_readable():
    """No file of dpom_warp/ over 600 lines, no function over 100 (split by job, not by size:
    docs/architecture.md says which file does what)."""
    import ast

    long_files, long_functions = [], []
    for path in sorted((ROOT / "dpom_warp").rglob("*.py")):
        text = path.read_text()
        if text.count("\n") > 600:
            long_files.append(f"{path.relative_to(ROOT)} ({text.count(chr(10))} lines)")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno >= 100:
                long_functions.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert not long_files, long_files
    assert not long_functions, long_functions


def test_the_generic_engine_reads_no_people_only_parameter():
    """The people-only tests (the behind cost, the top band, the joint test's lists) are a prior
    the engine is given (engine/people.py): no other file of the engine reads one of their
    parameters (model.behind_*, model.top_*) or builds the joint test's lists."""
    import re

    people = re.compile(r"\b(?:p|params|self\.params)\.(?:behind_|top_)\w+|JointLists\.of_batch")
    found = [f"{path.name}:{n}: {line.strip()}" for path in sorted((ROOT / "dpom_warp" / "engine").glob("*.py"))
             if path.name != "people.py"
             for n, line in enumerate(path.read_text().splitlines(), 1) if people.search(line)]
    assert not found, found
    assert people.search((ROOT / "dpom_warp" / "engine" / "people.py").read_text())  # the check can fail
