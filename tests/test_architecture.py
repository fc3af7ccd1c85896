"""Architecture rules as code: the import layers of .importlinter, no file over 400 lines, no function over
80, no use of another module's private names."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 400


def test_import_layers_and_no_cycles():
    """`lint-imports` (import-linter, pinned in environment.txt) keeps every contract in .importlinter."""
    lint = Path(sys.executable).with_name("lint-imports")
    assert lint.is_file(), f"lint-imports not found beside {sys.executable}: pip install -r environment.txt"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def test_no_library_file_exceeds_400_lines():
    long = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / "coursekit").rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"split these by concept (one concept per module, <= {MAX_LINES} lines): {long}"


MAX_FUNCTION_LINES = 80


def _library_sources() -> list[tuple[str, str, ast.Module]]:
    """(path relative to the repository, dotted module name, parsed tree) of every .py under coursekit/."""
    out = []
    for path in sorted((ROOT / "coursekit").rglob("*.py")):
        rel = path.relative_to(ROOT)
        parts = rel.with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out.append((str(rel), module, ast.parse(path.read_text(encoding="utf-8"), filename=str(rel))))
    return out


def _function_lengths(tree: ast.AST, prefix: str = "") -> list[tuple[str, int]]:
    """(qualified name, lines from the first decorator to the last line) of every function and method in ``tree``."""
    found = []
    scopes = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            found.append((prefix + node.name, node.end_lineno - first + 1))
        found += _function_lengths(node, f"{prefix}{node.name}." if isinstance(node, scopes) else prefix)
    return found


def long_functions(sources: list[tuple[str, str, ast.Module]], limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``path:name:lines`` of each function or method longer than ``limit`` lines."""
    return [f"{rel}:{name}:{n}" for rel, _, tree in sources for name, n in _function_lengths(tree) if n > limit]


def test_no_library_function_exceeds_80_lines():
    long = long_functions(_library_sources())
    assert not long, f"split these into steps that each do one thing (<= {MAX_FUNCTION_LINES} lines): {long}"


def _is_private(name: str) -> bool:
    """One leading underscore, not a dunder: ``_helper`` is private, ``__version__`` is not."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _private_module_refused(importer: str, target: str, modules: set[str]) -> bool:
    """True if ``importer`` may not use the module ``target`` because a private module on its path
    (``coursekit.commands._args``) belongs to a package ``importer`` is not in; False if ``target``
    is not a module of coursekit or no part of its path is private."""
    if target not in modules:
        return False
    parts = target.split(".")
    for i, part in enumerate(parts):
        if _is_private(part):
            owner = ".".join(parts[:i])
            return not (importer == owner or importer.startswith(owner + "."))
    return False


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The module a ``from ... import`` reads, with a relative one resolved against ``module``."""
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def private_uses(sources: list[tuple[str, str, ast.Module]]) -> list[str]:
    """``path:line: what`` of each use of another coursekit module's private name.

    Refused: ``from coursekit.x import _name`` (a private function, class or constant), a private
    module imported from outside its own package (``coursekit.commands._args`` is for the modules of
    ``coursekit.commands``), and ``name._attr`` / ``getattr(name, "_attr")`` where ``name`` was bound
    by importing a coursekit module or object (``PushTEnv._check_state``). A class's own and inherited
    members (``self._x``, ``cls._x``, ``super()._x``) are its own business.
    """
    modules = {module for _, module, _ in sources}
    found = []
    for rel, module, tree in sources:
        bound: dict[str, str] = {}  # local name -> the dotted coursekit module or object it was imported as
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found += [f"{rel}:{node.lineno}: {what}" for what in _import_findings(node, module, rel, modules, bound)]
        for node in ast.walk(tree):
            dotted = _imported_private_access(node, bound)
            if dotted and not _private_module_allowed_access(module, dotted, modules):
                found.append(f"{rel}:{node.lineno}: uses {dotted}, private to its module")
    return found


def _import_findings(node: ast.Import | ast.ImportFrom, module: str, rel: str, modules: set[str],
                     bound: dict[str, str]) -> list[str]:
    """What the import ``node`` of ``module`` takes that is private to another module; records in
    ``bound`` the coursekit module or object each name it binds stands for."""
    found = []
    if isinstance(node, ast.Import):
        for alias in node.names:
            if alias.name.split(".")[0] == "coursekit":
                local, target = (alias.asname, alias.name) if alias.asname else ("coursekit", "coursekit")
                bound[local] = target  # `import coursekit.x.y` binds coursekit itself
                if _private_module_refused(module, alias.name, modules):
                    found.append(f"imports the private module {alias.name}")
        return found
    source = _absolute(node, module, rel.endswith("__init__.py"))
    if source.split(".")[0] != "coursekit":
        return found
    if _private_module_refused(module, source, modules):
        found.append(f"imports the private module {source}")
    for alias in node.names:
        target = f"{source}.{alias.name}"
        bound[alias.asname or alias.name] = target
        if target in modules:
            if _private_module_refused(module, target, modules):
                found.append(f"imports the private module {target}")
        elif _is_private(alias.name):
            found.append(f"imports the private name {alias.name} of {source}")
    return found


def _imported_private_access(node: ast.AST, bound: dict[str, str]) -> str | None:
    """The dotted coursekit name of a private ``name.attr...`` or ``getattr(name, "_attr")`` on an imported name."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr" \
            and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str):
        obj, chain = node.args[0], [node.args[1].value]
    elif isinstance(node, ast.Attribute):
        obj, chain = node.value, [node.attr]
    else:
        return None
    if not _is_private(chain[-1]):
        return None
    while isinstance(obj, ast.Attribute):
        chain.insert(0, obj.attr)
        obj = obj.value
    if not (isinstance(obj, ast.Name) and obj.id in bound):
        return None
    return ".".join([bound[obj.id], *chain])


def _private_module_allowed_access(importer: str, dotted: str, modules: set[str]) -> bool:
    """True when ``dotted`` (``coursekit.commands._args``) is a private module its package's own modules may use."""
    return dotted in modules and not _private_module_refused(importer, dotted, modules)


def test_no_module_uses_another_modules_private_names():
    found = private_uses(_library_sources())
    assert not found, ("make these names public (a docstring, no underscore) or move the code to the module that "
                       "owns them:\n" + "\n".join(found))
