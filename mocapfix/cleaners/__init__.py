"""Registry of cleaners by name.

A cleaner module registers its classes with :func:`register` — the one place a cleaner
is listed: a new module in this package is found when the registry is first asked for a
name (:func:`registry`, :func:`lookup`, :func:`build`), which imports every module here.
None of them imports SciPy or PyWavelets at module level, so listing them all stays cheap
(tests/cleaners/test_cleaner_registry.py).
"""
from __future__ import annotations

import importlib
import pkgutil
import warnings

from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.errors import ConfigError

_REGISTRY: dict[str, type[Cleaner]] = {}
_loaded = False


def register(cls: type[Cleaner]) -> type[Cleaner]:
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise TypeError(f"two cleaners named {cls.name!r}")
    _REGISTRY[cls.name] = cls
    return cls


def _load() -> None:
    """Import every module of this package: each registers its cleaners as it is
    imported (the :func:`register` decorator is the one place a cleaner is listed)."""
    global _loaded
    if _loaded:
        return
    for module in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{module.name}")
    _loaded = True


def registry() -> dict[str, type[Cleaner]]:
    _load()
    return dict(sorted(_REGISTRY.items()))


def lookup(name: str) -> type[Cleaner] | None:
    """The cleaner class named ``name`` (None: no such cleaner)."""
    return _REGISTRY.get(name) or registry().get(name)


def build(name: str, step: str | None = None, **params) -> Cleaner:
    """The cleaner ``name`` with ``params``. From Python (no ``step``), a bare number for a
    physical parameter gets the rule a YAML config gets: read in the parameter's default
    unit, and said — here as a warning (``build("butterworth", cutoff=6)`` is 6 Hz)."""
    cls = lookup(name) if isinstance(name, str) else None
    if cls is None:
        reg = registry()
        raise ConfigError(f"{step or name}: unknown cleaner {name!r} "
                          f"(known: {', '.join(reg)})")
    if step is None:
        for p in cls.params:
            note = p.bare_number_note(params[p.name]) if p.name in params else None
            if note:
                warnings.warn(f"{name}: {note}", UserWarning, stacklevel=2)
    return cls(step=step, **params)


__all__ = ["Cleaner", "Param", "register", "registry", "lookup", "build"]
