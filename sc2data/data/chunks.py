"""The frame chunk codec: Zstandard-compressed, fletcher32-checksummed HDF5 chunks.

Frame datasets declare HDF5's standard filter pipeline (hdf5plugin's Zstd filter, then HDF5's
fletcher32), so any HDF5 reader with hdf5plugin decodes them and checks every checksum
(``sc2data verify`` reads them that way). The hot paths skip HDF5's per-call filter machinery,
which costs ~50 µs per chunk here (BENCHMARKS.md): the writer compresses each flush of chunks,
checksums many flushes' chunks at once and writes them with ``write_direct_chunk``; the reader
fetches raw chunks at the offsets of the shard's chunk index, verifies the fletcher32 checksums of
a whole batch in a few vectorised numpy calls, and decompresses. The bytes on disk are exactly
what HDF5's own pipeline would write.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import h5py
import hdf5plugin
import numpy as np
import zstandard

from sc2data.ground.errors import Sc2DataError

ZSTD_FILTER = 32015
"""HDF5 filter id of Zstandard (registered by hdf5plugin)."""
FLETCHER32_FILTER = int(h5py.h5z.FILTER_FLETCHER32)


class ChecksumError(Sc2DataError, OSError):
    """A chunk's fletcher32 checksum does not match its bytes: the file is damaged. An
    :class:`Sc2DataError` (commands print it as one line) and an ``OSError``, like h5py's own
    checksum failures."""


@dataclass(frozen=True)
class Codec:
    """How frame datasets are chunked and compressed (chosen by measurement, BENCHMARKS.md)."""

    level: int = 3
    """Zstandard level. On reduced-random sim frames stored in blocks, level 3 compresses as fast
    as level 1 and 12 % smaller (1,463 against 1,666 B/frame at 4-frame chunks); level 4 and up
    write markedly slower (BENCHMARKS.md)."""
    chunk_frames: int = 4
    """Frames per chunk. Consecutive frames are near identical, so longer chunks compress far
    better (paper layers in blocks, level 3: 2.1 KB/frame at 2, 1.5 KB at 4, 1.1 KB at 8), but a
    random stack decodes whole chunks of every block it reads: 4 frames keeps well under the
    2 KB/frame budget and reads random stacks ≈ 1.5× faster than 8 (BENCHMARKS.md)."""

    def dataset_kwargs(self) -> dict[str, Any]:
        """h5py ``create_dataset`` filter arguments: Zstd then fletcher32, as HDF5 applies them."""
        return {**hdf5plugin.Zstd(clevel=self.level), "fletcher32": True}

    def to_dict(self) -> dict[str, Any]:
        return {"name": "zstd+fletcher32", **asdict(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Codec:
        return cls(level=int(d["level"]), chunk_frames=int(d["chunk_frames"]))


def _fold(s: np.ndarray) -> np.ndarray:
    """HDF5's end-around-carry reduction of a Fletcher sum to 16 bits (0 only for a zero sum)."""
    return np.where(s == 0, 0, (s - 1) % 65535 + 1)


def fletcher32(payloads: Sequence[bytes | memoryview]) -> np.ndarray:
    """HDF5's fletcher32 (``H5_checksum_fletcher32``) of each payload, vectorised over all.

    HDF5 sums big-endian 16-bit words; an odd last byte counts as a word whose low byte is zero,
    so padding each payload to even length with a zero byte gives the same checksum.
    """
    if not payloads:
        return np.zeros(0, np.uint32)
    lens = np.fromiter((len(p) for p in payloads), np.int64, len(payloads))
    buf = b"".join(p if len(p) % 2 == 0 else bytes(p) + b"\0" for p in payloads)
    words = np.frombuffer(buf, ">u2").astype(np.uint64)
    n = (lens + 1) // 2
    starts = np.cumsum(n) - n
    if (n == 0).any():
        raise ValueError("fletcher32 of an empty payload")
    s1 = np.add.reduceat(words, starts)
    jw = np.add.reduceat(np.arange(len(words), dtype=np.uint64) * words, starts)
    # sum2 = Σ_j (n - j)·w_j over each payload's local word index j.
    s2 = n.astype(np.uint64) * s1 - (jw - starts.astype(np.uint64) * s1)
    return ((_fold(s2) << np.uint64(16)) | _fold(s1)).astype(np.uint32)


class ChunkEncoder:
    """Compresses frame blocks into HDF5 chunk payloads (Zstd frame + little-endian fletcher32)."""

    def __init__(self, codec: Codec) -> None:
        self._zstd = zstandard.ZstdCompressor(level=codec.level)

    def compress(self, blocks: Sequence[np.ndarray]) -> list[bytes]:
        """Zstd frames of ``blocks``, not yet checksummed (see :meth:`seal`)."""
        return [self._zstd.compress(np.ascontiguousarray(b).data) for b in blocks]

    @staticmethod
    def seal(compressed: Sequence[bytes]) -> list[bytes]:
        """Append each payload's fletcher32, as HDF5 stores it. One vectorised pass, so the
        writer seals many flushes' chunks at once (per flush it cost ≈ 7 µs a frame)."""
        sums = fletcher32(compressed)
        return [c + int(s).to_bytes(4, "little") for c, s in zip(compressed, sums, strict=True)]

    def encode(self, blocks: Sequence[np.ndarray]) -> list[bytes]:
        """Compressed and sealed HDF5 chunk payloads of ``blocks``."""
        return self.seal(self.compress(blocks))


class ChunkDecoder:
    """Verifies and decompresses raw chunks as stored on disk (payload + fletcher32)."""

    def __init__(self) -> None:
        self._zstd = zstandard.ZstdDecompressor()

    def _verified(self, raws: Sequence[bytes], wheres: Sequence[str]) -> list[memoryview]:
        """The payloads of ``raws`` once every checksum matched (one vectorised pass)."""
        payloads = [memoryview(r)[:-4] for r in raws]
        stored = np.frombuffer(b"".join(r[-4:] for r in raws), "<u4")
        bad = np.flatnonzero(fletcher32(payloads) != stored)
        if bad.size:
            raise ChecksumError(f"{wheres[bad[0]]}: fletcher32 checksum mismatch in {bad.size} "
                                f"chunk(s); the file is damaged")
        return payloads

    def decode(self, raws: Sequence[bytes], masks: Sequence[int], sizes: Sequence[int],
               wheres: Sequence[str]) -> list[bytes]:
        """Each chunk's decoded bytes (``sizes[i]`` of them). All checksums are verified first,
        in one vectorised pass, so chunks of many datasets are best decoded in one call; a
        mismatch raises :class:`ChecksumError` naming the first damaged chunk's dataset."""
        out = []
        for p, m, size, where in zip(self._verified(raws, wheres), masks, sizes, wheres,
                                     strict=True):
            try:
                data = bytes(p) if m & 1 else self._zstd.decompress(p, max_output_size=size)
            except zstandard.ZstdError as e:
                raise ChecksumError(f"{where}: a chunk does not decompress ({e})") from None
            if len(data) != size:
                raise ChecksumError(f"{where}: a chunk decodes to the wrong size; the file is "
                                    f"damaged")
            out.append(data)
        return out

    def decode_into(self, raws: Sequence[bytes], masks: Sequence[int], outs: Sequence[np.ndarray],
                    wheres: Sequence[str]) -> None:
        """:meth:`decode`, each chunk straight into its own contiguous array ``outs[i]``, which it
        must fill exactly: readers decode a batch's chunks into one array, with no joining copy."""
        for p, m, out, where in zip(self._verified(raws, wheres), masks, outs, wheres,
                                    strict=True):
            view = memoryview(out).cast("B")
            if m & 1:
                if len(p) != len(view):
                    raise ChecksumError(f"{where}: a chunk holds the wrong size; the file is "
                                        f"damaged")
                view[:] = p
                continue
            try:
                with self._zstd.stream_reader(p) as reader:
                    got = 0
                    while got < len(view) and (n := reader.readinto(view[got:])):
                        got += n
                    over = reader.read(1)
            except zstandard.ZstdError as e:
                raise ChecksumError(f"{where}: a chunk does not decompress ({e})") from None
            if got != len(view) or over:
                raise ChecksumError(f"{where}: a chunk decodes to the wrong size; the file is "
                                    f"damaged")


def fast_path_ok(ds: h5py.Dataset) -> bool:
    """True when ``ds`` uses exactly this module's pipeline (Zstd, then fletcher32)."""
    plist = ds.id.get_create_plist()
    if ds.chunks is None or plist.get_nfilters() != 2:
        return False
    return (plist.get_filter(0)[0], plist.get_filter(1)[0]) == (ZSTD_FILTER, FLETCHER32_FILTER)
