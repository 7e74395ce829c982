"""Registry of cleaners by name.

A cleaner module registers its classes with :func:`register`; :func:`build` makes one
from a config step. ``_WHERE`` maps every cleaner name to its module, so :func:`build`
imports only the modules a pipeline names (a clean with the default C3D steps does not
load scipy.signal, scipy.interpolate or pywt unless a step needs them); :func:`registry`
(listing every cleaner) imports them all. A module not in ``_WHERE`` can still register
its cleaners when it is imported.
"""
from __future__ import annotations

import importlib

from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.errors import ConfigError

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
    "mocapfix.cleaners.depth_skeleton",
    "mocapfix.cleaners.pma",
    "mocapfix.cleaners.mssa",
)
_loaded = False

#: cleaner name → module that registers it (tests check the two agree)
_WHERE = {
    "fill": "mocapfix.cleaners.fill",
    "gaussian": "mocapfix.cleaners.smooth",
    "butterworth": "mocapfix.cleaners.smooth",
    "wavelet": "mocapfix.cleaners.smooth",
    "kalman": "mocapfix.cleaners.smooth",
    "spikes": "mocapfix.cleaners.spikes",
    "fill_pca": "mocapfix.cleaners.pca_fill",
    "swaps": "mocapfix.cleaners.swaps",
    "rotation_smooth": "mocapfix.cleaners.rotations",
    "lowrank_isometry": "mocapfix.cleaners.lowrank_isometry",
    "trust": "mocapfix.cleaners.tsmc",
    "tsmc": "mocapfix.cleaners.tsmc",
    "pma": "mocapfix.cleaners.pma",
    "fill_ensemble": "mocapfix.cleaners.pma",
    "partlet_dictionary": "mocapfix.cleaners.partlet",
    "kinect_skeleton": "mocapfix.cleaners.depth_skeleton",
    "mssa": "mocapfix.cleaners.mssa",
    "euler_smooth": "mocapfix.cleaners.rotations",
    "rotation_outliers": "mocapfix.cleaners.rotations",
    "rotation_denoise": "mocapfix.cleaners.rotations",
}


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


def lookup(name: str) -> type[Cleaner] | None:
    """The cleaner class named ``name``, importing only its module when it is known."""
    if name not in _REGISTRY and name in _WHERE:
        importlib.import_module(_WHERE[name])
    return _REGISTRY.get(name) or registry().get(name)


def build(name: str, step: str | None = None, **params) -> Cleaner:
    cls = lookup(name) if isinstance(name, str) else None
    if cls is None:
        reg = registry()
        raise ConfigError(f"{step or name}: unknown cleaner {name!r} "
                          f"(known: {', '.join(reg)})")
    return cls(step=step, **params)


__all__ = ["Cleaner", "Param", "register", "registry", "lookup", "build"]
