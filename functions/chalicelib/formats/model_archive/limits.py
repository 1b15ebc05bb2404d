"""How much of an uploaded model archive drem will read: the bounds every scan is held to."""
from __future__ import annotations

import tarfile

from pydantic import BaseModel, ConfigDict, Field

KiB = 1024
MiB = 1024 * KiB


class ArchiveLimits(BaseModel):
    model_config = ConfigDict(frozen=True)

    max_compressed_bytes: int = Field(default=128 * MiB, gt=0)
    max_total_bytes: int = Field(default=256 * MiB, gt=0, description="sum of all members, uncompressed")
    max_member_bytes: int = Field(default=128 * MiB, gt=0)
    max_members: int = Field(default=64, gt=0)
    max_metadata_bytes: int = Field(default=64 * KiB, gt=0)
    max_meta_header_bytes: int = Field(default=16 * KiB, gt=0, description="GNU long-name and pax headers")
    max_path_length: int = Field(default=255, gt=0)

    @property
    def max_inflated_bytes(self) -> int:
        """Everything the decompressor may produce: member data plus headers, padding and the tar end record."""
        per_member_overhead = self.max_meta_header_bytes + 3 * tarfile.BLOCKSIZE
        return self.max_total_bytes + self.max_members * per_member_overhead + 2 * tarfile.RECORDSIZE


DEFAULT_LIMITS = ArchiveLimits()


def size_text(count: int) -> str:
    """A byte count as a racer reads it in a message."""
    if count >= MiB:
        return f"{count / MiB:.1f} MiB"
    if count >= KiB:
        return f"{count / KiB:.1f} KiB"
    return f"{count} bytes"
