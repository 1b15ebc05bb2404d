"""What a model may be called: its name becomes an S3 key part and a folder on the car."""
from __future__ import annotations

import re

from chalicelib.core.errors import InvalidInput

MODEL_NAME_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
ARCHIVE_SUFFIX = ".tar.gz"


class InvalidModelName(InvalidInput):
    pass


def validate_model_name(name: str) -> str:
    """A model name is 1-64 letters, digits, `-` or `_` (it becomes an S3 key part and a folder on the car)."""
    if not isinstance(name, str) or not MODEL_NAME_PATTERN.fullmatch(name):
        shown = repr(name[:70]) if isinstance(name, str) else type(name).__name__
        raise InvalidModelName(
            f"model name {shown} is not allowed: use 1-64 letters, digits, '-' or '_' (no spaces, dots or slashes)",
            field="name",
        )
    return name


def model_name_from_filename(filename: str) -> str:
    """`My-model_3.tar.gz` -> `My-model_3` (DREM's upload rule: `^[A-Za-z0-9_-]+\\.tar\\.gz$`)."""
    if not isinstance(filename, str) or not filename.endswith(ARCHIVE_SUFFIX):
        raise InvalidModelName("a model upload must be a .tar.gz file", field="file")
    return validate_model_name(filename[: -len(ARCHIVE_SUFFIX)])
