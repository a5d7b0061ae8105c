"""Format headers: every file and folder sc2data writes names its format and version.

One table of formats, one way to write a header and one check with one message style:
``PATH is not an sc2data KIND`` for a foreign file, ``PATH has KIND format V, not W; REMEDY`` for
one written by another version. The ids are spelled as they have been stored since each format's
first version (existing datasets, pair sets and checkpoints must keep reading), so the older
hyphenated ids of shards and datasets stay; formats added later use the dotted form
``sc2data.NAME``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sc2data.errors import Sc2DataError


@dataclass(frozen=True)
class Format:
    """One stored format: its id, current version, what a user calls it, and what to do about an
    old one."""

    id: str
    version: int
    kind: str
    remedy: str
    reads: tuple[int, ...] = ()
    """Older versions still read (and verified), never written into."""

    def header(self) -> dict[str, Any]:
        """The two fields that open every record of this format."""
        return {"format": self.id, "format_version": self.version}

    def check(self, found: Mapping[str, Any] | Any, where: object) -> int:
        """The version of ``found`` (a dict, HDF5 attrs, …); a one-line error unless it carries
        this header with the current version or one still read."""
        get = getattr(found, "get", None)
        if get is None or get("format") != self.id:
            raise Sc2DataError(f"{where} is not an sc2data {self.kind}")
        version = get("format_version")
        if version != self.version and version not in self.reads:
            raise Sc2DataError(f"{where} has {self.kind} format {version}, not {self.version}; "
                               f"{self.remedy}")
        return int(version)


SHARD = Format("sc2data-shard", 3, "shard", "regenerate it with this sc2data", reads=(2,))
"""2: frames in blocks (one HDF5 dataset per group and dtype). 3: its ``settings`` attribute
leaves out the dataset's episode count, so a shard's bytes do not depend on how many episodes
follow it and a dataset grows without rewriting its full shards."""
DATASET = Format("sc2data-dataset", 3, "dataset", "regenerate it with this sc2data", reads=(2,))
"""``dataset.json``; dataset format V holds shards of format V (2 and 3). A dataset of an
older format still read is readable and verifiable, but a rollout does not add to it."""
PACKED = Format("sc2data.packed", 1, "packed split", "rerun sc2data pair")
PAIRSET = Format("sc2data.pairset", 1, "pair set", "rerun sc2data pair")
CHECKPOINT = Format("sc2data.mem", 1, "model checkpoint", "retrain the model")
