"""The verdict on a model archive: its status, the reason a racer can act on, and the facts drem keeps."""
from __future__ import annotations

from enum import StrEnum
from typing import Literal

from pydantic import BaseModel, Field

from chalicelib.formats.model_metadata import ModelMetadata


class ArchiveStatus(StrEnum):
    """The verdict; the values are DREM's model status names."""

    AVAILABLE = "AVAILABLE"
    NOT_VALID = "NOT_VALID"
    QUARANTINED = "QUARANTINED"


ModelKind = Literal["tensorflow", "onnx"]
# model_metadata.json is kept on the model's record up to this size (a real one is 1-3 KB), so reading it later (a
# league push that brings the model) does not fetch and unpack the whole archive again.
METADATA_KEPT_BYTES = 16 * 1024


class ArchiveReport(BaseModel):
    status: ArchiveStatus
    reason: str | None = None
    model_kind: ModelKind | None = None
    model_member: str | None = None
    model_md5: str | None = None
    metadata_md5: str | None = None
    sensor: list[str] = Field(default_factory=list)
    action_space_type: str | None = None
    training_algorithm: str | None = None
    metadata: ModelMetadata | None = None
    metadata_json: str | None = None  # the file's own text (METADATA_KEPT_BYTES at most)
    member_count: int = 0
    total_size: int = 0

    @property
    def available(self) -> bool:
        return self.status is ArchiveStatus.AVAILABLE


class ArchiveProblem(Exception):
    """Stops a scan at the first thing wrong; becomes the report's status and reason."""

    def __init__(self, status: ArchiveStatus, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


def quarantine(reason: str) -> ArchiveProblem:
    return ArchiveProblem(ArchiveStatus.QUARANTINED, reason)


def not_valid(reason: str) -> ArchiveProblem:
    return ArchiveProblem(ArchiveStatus.NOT_VALID, reason)
