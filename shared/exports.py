"""Lazy public names for a package's ``__init__``: import a module only when a name is used.

A package lists its public names (``__all__``) with the module each comes from; the
module is imported on first access (PEP 562), so importing one small module of a
package (``walkstream.shared.errors`` for the command line) does not import all of it.

>>> getattr_, dir_ = lazy_exports("walkstream.shared", {"signed_area": "walkstream.shared.geometry"})
>>> getattr_("signed_area").__name__
'signed_area'
>>> dir_()
['signed_area']
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``exports`` maps a name to its module."""

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(module), name)

    def __dir__() -> list[str]:
        return sorted(exports)

    return __getattr__, __dir__
