"""Judging an uploaded model archive (`.tar.gz`) without trusting a byte of it.

An upload is hostile input. `inspect_archive` streams the archive once (`safe_tar`), entirely in memory, and never
extracts:

* QUARANTINED: anything that could write outside a sandbox if extracted (absolute paths, `..`, links, device files,
  fifos, NUL/backslash/drive-letter tricks, control, bidi-override and other invisible format characters in names),
  and any data hidden after the tar end marker (a later gzip member or tar members that `tar -i`, `bsdtar` or a
  careless extractor would still unpack).
* NOT_VALID: broken or unusable, with a reason a racer can act on (not gzip, truncated, not tar, too big, too many
  members, bad or missing `model_metadata.json`, no model file, duplicate names).
* AVAILABLE: the facts drem keeps about the model (kind, md5 of the model file and of the metadata, sensors, ...),
  once `layout` has found the model in one of the layouts drem accepts.
"""
from __future__ import annotations

from chalicelib.formats.model_archive.layout import (
    METADATA_MEMBERS,
    check_stock_car_metadata,
    metadata_member,
    model_file,
    read_metadata,
)
from chalicelib.formats.model_archive.limits import DEFAULT_LIMITS, ArchiveLimits
from chalicelib.formats.model_archive.report import ArchiveProblem, ArchiveReport, ArchiveStatus
from chalicelib.formats.model_archive.safe_tar import ArchiveSource, OpenOutput, SafeTarReader, TarFacts


def inspect_archive(source: ArchiveSource, *, limits: ArchiveLimits = DEFAULT_LIMITS) -> ArchiveReport:
    """Stream the archive once and return its verdict. Never raises for bad archive content (a path that does not
    exist is the caller's mistake and raises FileNotFoundError)."""
    return judge_archive(source, limits=limits)


def judge_archive(source: ArchiveSource, *, limits: ArchiveLimits, open_output: OpenOutput | None = None
                  ) -> ArchiveReport:
    """`inspect_archive`, with the regular files' bytes also written where `open_output` says (extraction)."""
    reader = SafeTarReader(limits, keep=METADATA_MEMBERS, open_output=open_output)
    try:
        return _judge(reader.read(source))
    except ArchiveProblem as problem:
        return _report(reader.facts, problem.status, problem.reason)


def _judge(facts: TarFacts) -> ArchiveReport:
    metadata_name = metadata_member(facts.kept)
    metadata = read_metadata(facts.kept[metadata_name])
    model_kind, model_member = model_file(metadata, facts.sizes)
    check_stock_car_metadata(metadata, facts.sizes)
    return _report(
        facts,
        ArchiveStatus.AVAILABLE,
        None,
        model_kind=model_kind,
        model_member=model_member,
        model_md5=facts.md5[model_member],
        metadata_md5=facts.md5[metadata_name],
        sensor=list(metadata.sensor),
        action_space_type=metadata.action_space_type.value,
        training_algorithm=metadata.training_origin,
        metadata=metadata,
    )


def _report(facts: TarFacts, status: ArchiveStatus, reason: str | None, **found) -> ArchiveReport:
    return ArchiveReport(status=status, reason=reason, member_count=facts.member_count, total_size=facts.total_size,
                         **found)
