"""The pair-set folder, defined once (``docs/pairset.md``): its files, and the check that they
are the bytes ``pairset.json`` recorded.

``pairset.json`` holds the recipe, the schema, the commands, the counts and ``fingerprint``: the
sha256 over ``pairs.parquet`` and the packed splits, in :func:`content_files` order. Every reader
(``pair`` deciding a folder is up to date, the trainer, ``evaluate``, ``verify``) checks it.
"""

from __future__ import annotations

from pathlib import Path

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import sha256_files
from sc2data.ground.vocab import SPLITS

PAIRS_FILE = "pairs.parquet"
META_FILE = "pairset.json"
PACKED_DIR = "packed"


def packed_path(folder: Path, split: str) -> Path:
    return folder / PACKED_DIR / f"{split}.h5"


def content_files(folder: Path) -> list[Path]:
    """The files the pair-set fingerprint covers, in order."""
    return [folder / PAIRS_FILE] + [packed_path(folder, s) for s in SPLITS]


def pairset_fingerprint(folder: Path) -> str:
    """The pair-set fingerprint: the sha256 over the folder's :func:`content_files` (recorded as
    ``fingerprint`` in ``pairset.json``, and as ``data_fingerprint`` by a run trained on it)."""
    return sha256_files(content_files(folder))


def check_content(folder: Path, recorded: str) -> None:
    """One-line error unless the folder's files are present and hash to ``recorded``."""
    missing = [p.relative_to(folder) for p in content_files(folder) if not p.is_file()]
    if missing:
        raise Sc2DataError(f"{folder} lacks {', '.join(map(str, missing))}; rerun sc2data pair")
    if pairset_fingerprint(folder) != recorded:
        raise Sc2DataError(f"{folder}: pairs.parquet or a packed split is damaged or was "
                           f"replaced (the files' sha256 differs from {META_FILE}); rerun "
                           f"sc2data pair, which rebuilds it")
