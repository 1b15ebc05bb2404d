"""Model archives (`.tar.gz` uploads), judged without trusting a byte. One job per module:

* `safe_tar`: the streaming reader (every byte counted, member names and kinds vetted, size bounds);
* `layout`: console, deepracer-on-aws and drem layouts (where the metadata and the model file are);
* `verdict`: `inspect_archive`, the AVAILABLE / NOT_VALID / QUARANTINED report (`report`);
* `extract`: `safe_extract` into a sandbox; `names`: model names; `limits`: the bounds; `streams`: byte wrappers.

Import from those modules; the names below are re-exported so older imports keep working.
"""
from chalicelib.formats.model_archive.extract import ArchiveRejected, ExtractedArchive, safe_extract
from chalicelib.formats.model_archive.limits import DEFAULT_LIMITS, ArchiveLimits
from chalicelib.formats.model_archive.names import InvalidModelName, model_name_from_filename, validate_model_name
from chalicelib.formats.model_archive.report import ArchiveReport, ArchiveStatus, ModelKind
from chalicelib.formats.model_archive.verdict import inspect_archive

__all__ = [
    "ArchiveLimits",
    "ArchiveRejected",
    "ArchiveReport",
    "ArchiveStatus",
    "DEFAULT_LIMITS",
    "ExtractedArchive",
    "InvalidModelName",
    "ModelKind",
    "inspect_archive",
    "model_name_from_filename",
    "safe_extract",
    "validate_model_name",
]
