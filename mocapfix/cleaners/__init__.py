"""Registry of cleaners by name.

A cleaner module registers its classes with :func:`register`; :func:`build` makes one
from a config step. Modules are listed in ``_MODULES`` and imported on first use.
"""
from __future__ import annotations

import importlib

from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.errors import ConfigError

_REGISTRY: dict[str, type[Cleaner]] = {}
_MODULES = (
    "mocapfix.cleaners.fill",
    "mocapfix.cleaners.smooth",
    "mocapfix.cleaners.spikes",
    "mocapfix.cleaners.pca_fill",
    "mocapfix.cleaners.swaps",
    "mocapfix.cleaners.rotations",
    "mocapfix.cleaners.lowrank_isometry",
    "mocapfix.cleaners.tsmc",
    "mocapfix.cleaners.partlet",
    "mocapfix.cleaners.mssa",
)
_loaded = False


def register(cls: type[Cleaner]) -> type[Cleaner]:
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise TypeError(f"two cleaners named {cls.name!r}")
    _REGISTRY[cls.name] = cls
    return cls


def _load() -> None:
    global _loaded
    if _loaded:
        return
    for mod in _MODULES:
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise
    _loaded = True


def registry() -> dict[str, type[Cleaner]]:
    _load()
    return dict(sorted(_REGISTRY.items()))


def build(name: str, step: str | None = None, **params) -> Cleaner:
    reg = registry()
    if name not in reg:
        raise ConfigError(f"{step or name}: unknown cleaner {name!r} "
                          f"(known: {', '.join(reg)})")
    return reg[name](step=step, **params)


__all__ = ["Cleaner", "Param", "register", "registry", "build"]
