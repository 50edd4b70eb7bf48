"""A second, independent reader of card images (not a test module: a helper the tests import).

It reads a FAT32 volume that starts at byte 0 of a file (what `heliquad sd-image` and
heliquad-fw-host make) straight from its bytes, by the FAT specification: the boot sector's
BPB, the first FAT's cluster chains and the 32-byte directory entries of 8.3 names. It shares
nothing with FatFs, so a log that reads the same through both was written as FAT says.
"""

from __future__ import annotations

import struct
from pathlib import Path

#: FAT32 entries at or above this end a chain (0x0FFFFFF8..0x0FFFFFFF).
END_OF_CHAIN = 0x0FFFFFF8
ATTR_DIRECTORY, ATTR_VOLUME_ID, ATTR_LONG_NAME = 0x10, 0x08, 0x0F


class Fat32Image:
    """The files of a FAT32 card image, by path ("LOGS/00000001.BIN")."""

    def __init__(self, path: Path):
        self.data = Path(path).read_bytes()
        (self.sector_bytes, self.cluster_sectors, reserved, n_fats) = struct.unpack_from(
            "<HBHB", self.data, 11)
        fat_sectors, = struct.unpack_from("<I", self.data, 36)
        self.root_cluster, = struct.unpack_from("<I", self.data, 44)
        if self.data[510:512] != b"\x55\xaa" or fat_sectors == 0:
            raise ValueError(f"{path}: not a FAT32 volume at byte 0")
        self.fat_at = reserved * self.sector_bytes
        self.data_at = (reserved + n_fats * fat_sectors) * self.sector_bytes
        self.cluster_bytes = self.cluster_sectors * self.sector_bytes

    def _chain(self, cluster: int) -> list[int]:
        chain = []
        while 2 <= cluster < END_OF_CHAIN:
            if cluster in chain:
                raise ValueError(f"cluster chain loops at {cluster}")
            chain.append(cluster)
            cluster = struct.unpack_from("<I", self.data, self.fat_at + 4 * cluster)[0] & 0x0FFFFFFF
        return chain

    def _cluster(self, cluster: int) -> bytes:
        at = self.data_at + (cluster - 2) * self.cluster_bytes
        return self.data[at:at + self.cluster_bytes]

    def entries(self, cluster: int) -> dict[str, tuple[int, int, int]]:
        """A directory's entries: name -> (attributes, first cluster, size)."""
        raw = b"".join(self._cluster(c) for c in self._chain(cluster))
        out = {}
        for at in range(0, len(raw), 32):
            entry = raw[at:at + 32]
            if entry[0] == 0:
                break
            attr = entry[11]
            if entry[0] == 0xE5 or attr == ATTR_LONG_NAME or attr & ATTR_VOLUME_ID:
                continue
            base, ext = entry[0:8].decode().rstrip(), entry[8:11].decode().rstrip()
            hi, lo = struct.unpack_from("<H", entry, 20)[0], struct.unpack_from("<H", entry, 26)[0]
            out[base + ("." + ext if ext else "")] = (attr, hi << 16 | lo,
                                                        struct.unpack_from("<I", entry, 28)[0])
        return out

    def _entry(self, path: str) -> tuple[int, int, int]:
        attr, cluster, size = ATTR_DIRECTORY, self.root_cluster, 0
        for part in path.strip("/").split("/"):
            if not attr & ATTR_DIRECTORY:
                raise FileNotFoundError(path)
            found = self.entries(cluster)
            if part not in found:
                raise FileNotFoundError(path)
            attr, cluster, size = found[part]
        return attr, cluster, size

    def listdir(self, path: str = "") -> list[str]:
        cluster = self._entry(path)[1] if path.strip("/") else self.root_cluster
        return sorted(n for n in self.entries(cluster) if n not in (".", ".."))

    def offset(self, path: str) -> int:
        """Where a file's first byte is in the image."""
        return self.data_at + (self._entry(path)[1] - 2) * self.cluster_bytes

    def read(self, path: str) -> bytes:
        _, cluster, size = self._entry(path)
        return b"".join(self._cluster(c) for c in self._chain(cluster))[:size]
