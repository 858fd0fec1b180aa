"""Layering of the package, read from the source with ``ast`` (nothing is imported).

* no import circle, counting function-local imports (a local import hides a circle, it does not remove it);
* no module imports one of a higher layer (``LAYERS``, the order of docs/architecture.md "Layers");
* no private name crosses modules (``from x import _name`` or ``x._name`` with ``x`` a package module);
* function-local package imports only where ``KNOWN_LOCAL_IMPORTS`` says why.

``KNOWN_*`` list what is still left, each with what is to be done; an entry that is no longer needed fails
too, so the lists only shrink.
"""
from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = "tissuemech"

#: bottom to top; a module may import modules of its own layer or below. Keyed by the first name under
#: ``tissuemech`` (a subpackage counts as one).
LAYERS: tuple[frozenset[str], ...] = tuple(frozenset(names.split()) for names in (
    "canonical units stats sourcehash numba_cache noise",
    "records",
    "models spectra curves lve",
    "fitting io synth plots posterior cards_febio cards_niftysim pipeline scopes",
    "adequacy ranking material cards tts",
    "diagnosis stages fem uq",
    "summary cli regression analysis",
))

#: import circles still left (as sorted module tuples) -> what is to be done
KNOWN_CIRCLES: dict[tuple[str, ...], str] = {}

#: (importing module, imported module, private name) still left -> what is to be done
KNOWN_PRIVATE: dict[tuple[str, str, str], str] = {}

#: modules whose function-local package imports are still left -> what is to be done
KNOWN_LOCAL_IMPORTS: dict[str, str] = {
    "tissuemech.diagnosis.figures": "the figure writers: keep matplotlib (through plots) out of the diagnosis",
    "tissuemech.tts": "the optional mastercurve figure: keeps matplotlib out of every import of tts (the diagnosis "
                      "imports tts for run temperatures)",
}


def _module_files() -> dict[str, Path]:
    mods = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


MODULES = _module_files()


def _owner(name: str) -> str | None:
    """The package module that ``name`` (a module or ``module.attribute``) lives in."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


class _Import:
    def __init__(self, module: str, target: str, name: str | None, local: bool, line: int):
        self.module, self.target, self.name, self.local, self.line = module, target, name, local, line


def _imports(module: str, path: Path) -> tuple[list[_Import], list[tuple[str, str, int]]]:
    """Package imports of one module, and its ``alias._name`` uses (alias bound to a package module)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_package = path.name == "__init__.py"
    found: list[_Import] = []
    aliases: dict[str, str] = {}

    def visit(node, local: bool, type_checking: bool):
        for child in ast.iter_child_nodes(node):
            child_local = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            tc = type_checking or (isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test))
            if isinstance(child, ast.Import) and not tc:
                for a in child.names:
                    if a.name.startswith(PACKAGE) and _owner(a.name):
                        found.append(_Import(module, _owner(a.name), None, local, child.lineno))
                        if a.asname:
                            aliases[a.asname] = _owner(a.name)
            elif isinstance(child, ast.ImportFrom) and not tc:
                if child.level:
                    base = module.split(".")
                    if not is_package:
                        base = base[:-1]
                    base = base[:len(base) - (child.level - 1)]
                    source = ".".join(base + ([child.module] if child.module else []))
                else:
                    source = child.module or ""
                if source.startswith(PACKAGE):
                    for a in child.names:
                        full = f"{source}.{a.name}"
                        if full in MODULES:             # from package import submodule
                            found.append(_Import(module, full, None, local, child.lineno))
                            aliases[a.asname or a.name] = full
                        else:
                            found.append(_Import(module, _owner(source), a.name, local, child.lineno))
            visit(child, child_local, tc)

    visit(tree, False, False)
    private_attrs = [(aliases[n.value.id], n.attr, n.lineno) for n in ast.walk(tree)
                     if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in aliases
                     and n.attr.startswith("_") and not n.attr.startswith("__")]
    return found, private_attrs


IMPORTS: dict[str, list[_Import]] = {}
PRIVATE_ATTRS: dict[str, list[tuple[str, str, int]]] = {}
for _mod, _path in MODULES.items():
    IMPORTS[_mod], PRIVATE_ATTRS[_mod] = _imports(_mod, _path)


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if len(parts) < 2:
        return None
    return next((i for i, names in enumerate(LAYERS) if parts[1] in names), None)


def _strongly_connected(edges: dict[str, set[str]]) -> list[tuple[str, ...]]:
    """Tarjan's strongly connected components with more than one module (iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[tuple[str, ...]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == node:
                        break
                if len(comp) > 1:
                    out.append(tuple(sorted(comp)))
    return out


def test_every_module_has_a_layer():
    missing = sorted({m.split(".")[1] for m in MODULES if "." in m and _layer(m) is None})
    assert not missing, f"add these to LAYERS here and to docs/architecture.md 'Layers': {missing}"


def test_no_import_circle():
    edges: dict[str, set[str]] = defaultdict(set)
    for imports in IMPORTS.values():
        for imp in imports:
            if imp.target != imp.module:
                edges[imp.module].add(imp.target)
    circles = set(_strongly_connected(edges))
    assert circles <= set(KNOWN_CIRCLES), f"import circles: {sorted(circles - set(KNOWN_CIRCLES))}"
    assert set(KNOWN_CIRCLES) <= circles, f"fixed, remove from KNOWN_CIRCLES: {sorted(set(KNOWN_CIRCLES) - circles)}"


def test_no_import_from_a_higher_layer():
    upward = sorted(f"{imp.module}:{imp.line} imports {imp.target}"
                    for imports in IMPORTS.values() for imp in imports
                    if _layer(imp.module) is not None and _layer(imp.target) is not None
                    and _layer(imp.target) > _layer(imp.module))
    assert not upward, "\n".join(upward)


def test_no_private_name_crosses_modules():
    found = {(imp.module, imp.target, imp.name): imp.line for imports in IMPORTS.values() for imp in imports
             if imp.name and imp.name.startswith("_") and not imp.name.startswith("__") and imp.target != imp.module}
    for module, uses in PRIVATE_ATTRS.items():
        for target, name, line in uses:
            if target != module:
                found.setdefault((module, target, name), line)
    unexpected = sorted(f"{m}:{line} uses {t}.{n}" for (m, t, n), line in found.items()
                        if (m, t, n) not in KNOWN_PRIVATE)
    assert not unexpected, "\n".join(unexpected)
    stale = sorted(set(KNOWN_PRIVATE) - set(found))
    assert not stale, f"fixed, remove from KNOWN_PRIVATE: {stale}"


def test_function_local_package_imports_are_known():
    local = defaultdict(list)
    for imports in IMPORTS.values():
        for imp in imports:
            if imp.local:
                local[imp.module].append(f"{imp.module}:{imp.line} imports {imp.target}")
    unexpected = sorted(line for m, lines in local.items() if m not in KNOWN_LOCAL_IMPORTS for line in lines)
    assert not unexpected, "import at module level (or add a reason):\n" + "\n".join(unexpected)
    stale = sorted(set(KNOWN_LOCAL_IMPORTS) - set(local))
    assert not stale, f"fixed, remove from KNOWN_LOCAL_IMPORTS: {stale}"


def test_the_checks_see_a_circle_and_a_private_import(tmp_path):
    """The parser finds what it is meant to find (a guard against a check that passes on anything)."""
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _strongly_connected(edges) == [("a", "b", "c")]
    path = tmp_path / "m.py"
    path.write_text("from tissuemech.fitting import _curve_and_rows\nfrom tissuemech import stats as st\n"
                    "def f():\n    from tissuemech.models import qlv\n    return st._pack(1, 0)\n")
    imports, attrs = _imports("tissuemech.fake", path)
    assert {(i.target, i.name, i.local) for i in imports} == {
        ("tissuemech.fitting", "_curve_and_rows", False), ("tissuemech.stats", None, False),
        ("tissuemech.models.qlv", None, True)}
    assert attrs == [("tissuemech.stats", "_pack", 5)]
