"""Where the project's own files live: the dataset registry and the per-dataset configs.

In a source checkout (``uv run``) they are the repository's ``data/`` and ``configs/`` folders; in
an installed wheel they are packaged under ``slam/_resources/``. Nothing here touches user data.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
_REPO = _PACKAGE.parent


def resource_dir(name: str) -> Path:
    """Return the folder ``name`` (``"configs"`` or ``"data"``) of the project's own files."""
    packaged = _PACKAGE / "_resources" / name
    if packaged.is_dir():
        return packaged
    return _REPO / name


def registry_path() -> Path:
    """Path of ``datasets.toml``, the dataset registry."""
    return resource_dir("data") / "datasets.toml"


def config_dir() -> Path:
    """Folder of the shipped configurations (``<dataset>.toml`` and ``grid/*.toml``)."""
    return resource_dir("configs")
