"""Shipped configs and rule sets (package data), nameable by preset name.

``-c optical-c3d`` means ``mocapfix/configs/optical-c3d.yaml`` wherever mocapfix is
installed; ``-r optical-gait`` means ``mocapfix/configs/rules/optical-gait.yaml``. A path
that exists always wins over a preset of the same name.
"""
from __future__ import annotations

from pathlib import Path

from mocapfix.core.errors import ConfigError

#: the installed package (its data folders hang off it)
PACKAGE_DIR = Path(__file__).resolve().parents[1]
CONFIG_DIR = PACKAGE_DIR / "configs"
RULES_DIR = CONFIG_DIR / "rules"
#: trained models shipped with mocapfix
MODELS_DIR = PACKAGE_DIR / "data" / "models"


def config_names() -> list[str]:
    return sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))


def config_summary(path: Path, width: int = 90) -> str:
    """The first sentence of a shipped file's leading comment (what it is for)."""
    words = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        words.append(line.lstrip("# ").strip())
    text = " ".join(w for w in words if w)
    for stop in (". ",):
        if stop in text:
            text = text[:text.index(stop) + 1]
    return text if len(text) <= width else text[:width - 1].rstrip() + "…"


def resolve_config(name_or_path) -> Path:
    """A pipeline config by path, or a shipped one by preset name."""
    return resolve_preset(name_or_path, CONFIG_DIR, "config", config_names(),
                          "; `mocapfix configs` lists them")


def resolve_preset(name_or_path, folder: Path, kind: str, names: list[str],
                   more: str = "") -> Path:
    """A ``kind`` file by path, or a shipped preset of ``folder`` by name (``kinect``,
    ``kinect.yaml``, or ``<folder name>/kinect`` as in the repository). A path that exists
    wins; otherwise one error naming the presets (``names``; ``more`` appended)."""
    path = Path(name_or_path)
    if path.exists() and not path.is_dir():     # a file, or a pipe: -c <(…)
        return path
    text = str(name_or_path)
    stem = text[:-5] if text.endswith(".yaml") else text
    preset = folder / f"{Path(stem).name}.yaml"
    if (("/" not in text) or text.startswith(f"{folder.name}/")) and preset.is_file():
        return preset               # (also when a folder of that name is here: -c kinect)
    if path.is_dir():
        raise ConfigError(f"{name_or_path}: is a folder, not a {kind} file")
    raise ConfigError(f"{name_or_path}: no such {kind} file or preset "
                      f"(presets: {', '.join(names)}{more})")
