"""What every shard and dataset record (``dataset.json``) keeps of where it came from."""

from __future__ import annotations

import platform
from importlib import metadata


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def versions() -> dict[str, str]:
    """Versions of sc2data and of the packages that shape its data."""
    return {
        "sc2data": _version("sc2data"),
        "pysc2": _version("pysc2"),
        "numpy": _version("numpy"),
        "h5py": _version("h5py"),
        "pyarrow": _version("pyarrow"),
        "python": platform.python_version(),
    }
