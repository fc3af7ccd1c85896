"""Lazy attribute loading for package ``__init__`` modules: import a heavy submodule on first use.

``import coursekit`` (or ``coursekit.envs``, ``coursekit.viz``, ...) must stay cheap: torch,
mujoco and meshcat are imported only when a name that needs them is first touched. Each
package lists its public names in a table and installs the loader::

    __getattr__, __dir__ = lazy_loader(__name__, {"PushTEnv": "coursekit.envs.pusht", ...})

A table value is ``"module"`` (the attribute of the same name in that module),
``"module:object"`` (a differently named object) or ``"module:"`` (the module itself).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_loader(package: str, table: Mapping[str, str], submodules: bool = False
                ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package ``package`` that resolves the names of ``table``.

    Resolved values are cached in the package's namespace, so each name is imported once.
    ``submodules=True`` also resolves any submodule of the package by name (``coursekit.viz.x``).
    """
    names = sorted(table)

    def __getattr__(name: str) -> Any:
        target = table.get(name)
        if target is None:
            if submodules and not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}") is not None:
                return importlib.import_module(f"{package}.{name}")
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module_name, sep, obj = target.partition(":")
        module = importlib.import_module(module_name)
        value = module if (sep and not obj) else getattr(module, obj or name)
        setattr(sys.modules[package], name, value)  # cache: later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(names).union(getattr(sys.modules[package], "__all__", ())))

    return __getattr__, __dir__
