"""The layout rules of the code base: short functions, no import cycle (counting the imports
inside functions, which run too), no module reaching into another's private names, no private
module or attribute of scipy, numba, pyFFTW or viser outside `app/viser_private.py`, and a
library that never imports the web app."""

from __future__ import annotations

import ast
import re
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE_DIRS = ("autotrack", "app", "benchmarks")
MAX_FUNCTION_LINES = 80
NUMBA_DECORATORS = {"njit", "jit", "vectorize", "guvectorize"}
DEPENDENCIES = ("scipy", "numba", "pyfftw", "viser")
"""Dependencies whose private modules and attributes the code must not use."""
VISER_PRIVATE = "app/viser_private.py"
"""The one module allowed to use viser's privates (where viser has no public hook)."""
_DEPENDENCY_PRIVATE_PATH = re.compile(
    rf"^(?:{'|'.join(DEPENDENCIES)})(?:\.\w+)*\._(?!_)\w*(?:\.\w+)*$"
)


def _sources(dirs: Iterable[str] = SOURCE_DIRS) -> list[Path]:
    return sorted(path for name in dirs for path in (ROOT / name).rglob("*.py"))


def _relative(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


IMPORT_NAME_OF_DIR = {"app": "autotrack_studio"}
"""Source folders installed under another name (pyproject.toml's package-dir)."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    parts = (IMPORT_NAME_OF_DIR.get(parts[0], parts[0]), *parts[1:])
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _decorator_names(node: ast.FunctionDef | ast.AsyncFunctionDef) -> set[str]:
    names = set()
    for decorator in node.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        if isinstance(target, ast.Attribute):
            names.add(target.attr)
        elif isinstance(target, ast.Name):
            names.add(target.id)
    return names


def _long_functions(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        if _decorator_names(node) & NUMBA_DECORATORS:
            continue
        first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
        length = node.end_lineno - first + 1
        if length > MAX_FUNCTION_LINES:
            yield f"{_relative(path)}:{node.lineno} {node.name} ({length} lines)"


# --- imports ------------------------------------------------------------------------------------


def _run_time_imports(tree: ast.Module) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import that can run: at module level, inside functions and classes, under `try`
    or `if` at any depth; not those under `if TYPE_CHECKING:` (they never run)."""
    pending: list[ast.AST] = [tree]
    while pending:
        node = pending.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            pending.extend(node.orelse)
        else:
            pending.extend(ast.iter_child_nodes(node))


def _absolute_module(node: ast.ImportFrom, module_name: str, is_package: bool) -> str:
    """The module an ImportFrom names, relative imports resolved against `module_name`."""
    if node.level == 0:
        return node.module or ""
    parts = module_name.split(".")
    base = parts if is_package else parts[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imported_modules(
    node: ast.Import | ast.ImportFrom, module_name: str, is_package: bool, known: set[str]
) -> list[str]:
    """The project modules an import statement loads (`from pkg import mod` loads pkg.mod)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names if alias.name in known]
    base = _absolute_module(node, module_name, is_package)
    targets = [
        f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names
    ]
    return [target for target in targets if target in known]


def _import_graph(paths: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the project modules it imports at run time (at any depth)."""
    known = set(paths)
    graph: dict[str, set[str]] = {name: set() for name in paths}
    for name, path in paths.items():
        is_package = path.name == "__init__.py"
        for node in _run_time_imports(ast.parse(path.read_text(encoding="utf-8"))):
            graph[name] |= set(_imported_modules(node, name, is_package, known)) - {name}
    return graph


def _project_modules(dirs: Iterable[str] = SOURCE_DIRS) -> dict[str, Path]:
    return {_module_name(path): path for path in _sources(dirs)}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of `graph` (a list of modules, first repeated last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        stack.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == 1:
                return [*stack[stack.index(target) :], target]
            if target not in state and (found := visit(target)):
                return found
        stack.pop()
        state[module] = 2
        return None

    for module in sorted(graph):
        if module not in state and (found := visit(module)):
            return found
    return None


# --- private names ------------------------------------------------------------------------------


def _names_defined(tree: ast.Module) -> set[str]:
    """Every name a module defines or binds: functions, classes, methods, assigned names and
    attributes (`self._x = ...`), arguments and import aliases."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store | ast.Del):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.alias):
            names.add(node.asname or node.name.split(".")[0])
    return names


def _module_aliases(tree: ast.Module, project: set[str]) -> dict[str, str]:
    """Local name -> module, for every `import x.y [as z]` and `from x import module`."""
    aliases: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    aliases[alias.asname] = alias.name
                else:
                    aliases[alias.name.split(".")[0]] = alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                if full in project or node.module.split(".")[0] in DEPENDENCIES:
                    aliases[alias.asname or alias.name] = full
    return aliases


def _top(module: str) -> str:
    return module.split(".")[0]


def _private_imports(tree: ast.Module, own: str, project: set[str]) -> Iterator[tuple[int, str]]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if _DEPENDENCY_PRIVATE_PATH.match(alias.name):
                    yield node.lineno, f"import {alias.name}"
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if _DEPENDENCY_PRIVATE_PATH.match(node.module):
                yield node.lineno, f"from {node.module} import ..."
                continue
            theirs = _top(node.module) in DEPENDENCIES or (
                node.module in project and node.module != own
            )
            for alias in node.names:
                if theirs and _is_private(alias.name):
                    yield node.lineno, f"from {node.module} import {alias.name}"


def _private_attributes(
    tree: ast.Module, own: str, project: set[str], project_privates: dict[str, set[str]]
) -> Iterator[tuple[int, str]]:
    """`x._name` where x is another project module or a dependency's module, or an object
    whose `_name` this module does not define but another project module does."""
    defined_here = _names_defined(tree)
    aliases = _module_aliases(tree, project)
    defined_elsewhere = set().union(
        *(names for module, names in project_privates.items() if module != own)
    )
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute) or not _is_private(node.attr):
            continue
        owner = ast.unparse(node.value)
        if owner in ("self", "cls", "super()"):
            continue
        root = aliases.get(owner.split(".")[0])
        module = None if root is None else ".".join([root, *owner.split(".")[1:]])
        if (
            module is not None
            and (_top(module) in DEPENDENCIES or (module in project and module != own))
            or module is None
            and node.attr not in defined_here
            and node.attr in defined_elsewhere
        ):
            yield node.lineno, ast.unparse(node)


def _private_strings(tree: ast.Module) -> Iterator[tuple[int, str]]:
    """A dependency's private module named in a string (`load("scipy.fft._pocketfft")`)."""
    for node in ast.walk(tree):
        is_text = isinstance(node, ast.Constant) and isinstance(node.value, str)
        if is_text and _DEPENDENCY_PRIVATE_PATH.match(node.value):
            yield node.lineno, repr(node.value)


def _private_uses(paths: dict[str, Path]) -> list[str]:
    """Every use of another module's private name, or of a dependency's private module or
    attribute, in the modules `paths` (outside app/viser_private.py)."""
    project = set(paths)
    trees = {name: ast.parse(path.read_text(encoding="utf-8")) for name, path in paths.items()}
    project_privates = {
        name: {n for n in _names_defined(tree) if _is_private(n)} for name, tree in trees.items()
    }
    found = []
    for name, tree in trees.items():
        if _relative(paths[name]) == VISER_PRIVATE:
            continue
        uses = [
            *_private_imports(tree, name, project),
            *_private_attributes(tree, name, project, project_privates),
            *_private_strings(tree),
        ]
        found += [f"{_relative(paths[name])}:{line} {text}" for line, text in sorted(uses)]
    return found


# --- the rules ----------------------------------------------------------------------------------


def test_no_function_is_longer_than_the_limit_outside_numba_kernels() -> None:
    long = [entry for path in _sources() for entry in _long_functions(path)]
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_imports_have_no_cycles_counting_imports_inside_functions() -> None:
    assert _cycle(_import_graph(_project_modules())) is None


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_the_import_graph_sees_imports_inside_functions(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("def f():\n    from pkg.b import g\n    return g\n")
    (package / "b.py").write_text("import pkg.a\n\ndef g():\n    return 1\n")
    (package / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import a\n"
    )
    paths = {f"pkg.{p.stem}": p for p in package.glob("[abc].py")}
    graph = _import_graph(paths)
    assert graph == {"pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": set()}
    assert _cycle(graph) == ["pkg.a", "pkg.b", "pkg.a"]


def test_no_module_uses_private_names_of_another_or_of_scipy_numba_pyfftw_viser() -> None:
    found = _private_uses(_project_modules())
    assert not found, f"private names used across modules: {found}"


def test_the_private_name_rule_catches_each_kind_of_use(tmp_path: Path, monkeypatch) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "owner.py").write_text(
        "class Thing:\n    def _helper(self):\n        return self._state\n\n"
        "def _scan():\n    return 1\n"
    )
    (package / "user.py").write_text(
        "import scipy.fft._pocketfft\n"
        "from numba.core import _private_thing\n"
        "from pkg.owner import _scan\n"
        "from pkg import owner\n"
        "import viser\n\n"
        "def use(thing, handle):\n"
        "    owner._scan()\n"
        "    thing._helper()\n"
        "    viser._messages\n"
        "    return load('scipy.optimize._minpack')\n"
    )
    (package / "fine.py").write_text(
        "import argparse\nfrom pkg.owner import Thing\n\n"
        "class Other:\n    def _own(self, other):\n        return other._own(self)\n\n"
        "def f(p: argparse._SubParsersAction):\n    return Thing()\n"
    )
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    paths = {f"pkg.{p.stem}": p for p in package.glob("*.py") if p.stem != "__init__"}
    found = [entry.split(" ", 1)[1] for entry in _private_uses(paths)]
    assert found == [
        "import scipy.fft._pocketfft",
        "from numba.core import _private_thing",
        "from pkg.owner import _scan",
        "owner._scan",
        "thing._helper",
        "viser._messages",
        "'scipy.optimize._minpack'",
    ]


LAYERS = (
    ("autotrack.errors", "autotrack.params", "autotrack.result"),
    ("autotrack.io",),
    ("autotrack.tracker", "autotrack.localization"),
    ("autotrack.sessions",),
    ("autotrack.pipeline",),
    ("autotrack.evaluation", "autotrack.synthetic", "autotrack.cli"),
)
"""The library's layers (docs/architecture.md), lowest first: a module imports only its own
layer and those below (modules outside them, e.g. `autotrack.machine`, are helpers any may use)."""


def _layer(module: str) -> int | None:
    for index, packages in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in packages):
            return index
    return None


def test_the_library_imports_only_downwards_through_its_layers() -> None:
    upward = [
        f"{module} -> {target}"
        for module, targets in _import_graph(_project_modules(("autotrack",))).items()
        for target in sorted(targets)
        if _layer(module) is not None
        and _layer(target) is not None
        and _layer(target) > _layer(module)
    ]
    assert not upward, f"imports against the layers: {upward}"


def test_the_library_never_imports_the_app() -> None:
    offenders = []
    for path in (ROOT / "autotrack").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            if any(name.split(".")[0] in ("app", "autotrack_studio") for name in names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders
