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
