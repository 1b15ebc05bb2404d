"""One vetting of member names and kinds for every archive and export drem reads: the rules themselves, and that
the model validator, the league reader and the event import each apply all of them."""
from __future__ import annotations

import io
import json
import os
import tarfile
from pathlib import Path

import pytest

from chalicelib.formats.event_export.reader import read_export as read_event_export
from chalicelib.formats.event_export.records import FORMAT, FORMAT_VERSION, MANIFEST, InvalidExport
from chalicelib.formats.event_export.writer import checksums, json_bytes
from chalicelib.formats.league_export import read_export as read_league_export
from chalicelib.formats.model_archive.report import ArchiveStatus
from chalicelib.formats.model_archive.verdict import inspect_archive
from drem_archive.member_names import (
    HostileMember,
    MalformedMember,
    vet_folder_file,
    vet_member_name,
    vet_member_type,
)
from tests.unit.league_helpers import raw_tar_gz

pytestmark = pytest.mark.unit

HOSTILE_NAMES = {
    "parent folder": "../../etc/hyperparameters.json",
    "parent folder inside": "ip/../../hyperparameters.json",
    "absolute": "/etc/hyperparameters.json",
    "backslash": "ip\\..\\hyperparameters.json",
    "drive letter": "C:/hyperparameters.json",
    "NUL": "ip/hyper\x00parameters.json",
    "control character": "ip/hyper\x1bparameters.json",
    "bidi override": "ip/hyper\u202enosj.parameters",
    "zero-width joiner": "ip/hyper\u200dparameters.json",
    "line separator": "ip/hyper\u2028parameters.json",
    "not UTF-8": "ip/hyper\udcffparameters.json",
}
# tarfile cuts a name at its first NUL when reading, so that one never reaches a reader through tarfile.
IN_TAR = {case: raw for case, raw in HOSTILE_NAMES.items() if "\x00" not in raw}


@pytest.mark.parametrize("raw", HOSTILE_NAMES.values(), ids=HOSTILE_NAMES.keys())
def test_hostile_names_are_refused_as_hostile(raw: str) -> None:
    with pytest.raises(HostileMember):
        vet_member_name(raw)


@pytest.mark.parametrize("raw", ["ip//hyperparameters.json", "ip/./hyperparameters.json", "a" * 300])
def test_unusable_names_are_refused_as_malformed(raw: str) -> None:
    with pytest.raises(MalformedMember):
        vet_member_name(raw)


def test_plain_names_are_normalised_and_the_root_folder_is_none() -> None:
    assert vet_member_name("./agent/model.pb") == "agent/model.pb"
    assert vet_member_name("agent/") == "agent"
    assert vet_member_name("./") is None
    with pytest.raises(MalformedMember, match="nested more than 3"):
        vet_member_name("a/b/c/d", max_depth=3)


@pytest.mark.parametrize("kind", [tarfile.SYMTYPE, tarfile.LNKTYPE, tarfile.CHRTYPE, tarfile.BLKTYPE,
                                  tarfile.FIFOTYPE, b"V"])
def test_members_other_than_files_and_folders_are_hostile(kind: bytes) -> None:
    member = tarfile.TarInfo("agent/model.pb")
    member.type, member.linkname = kind, "/etc/passwd"
    with pytest.raises(HostileMember):
        vet_member_type(member, "agent/model.pb")


def test_a_link_anywhere_on_a_folder_path_is_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.json").write_text("{}")
    root = tmp_path / "export"
    (root / "real").mkdir(parents=True)
    (root / "real" / "plain.json").write_text("{}")
    (root / "linked-file.json").symlink_to(outside / "secret.json")
    (root / "linked-folder").symlink_to(outside)
    os.mkfifo(root / "pipe.json")
    assert vet_folder_file(root, "real/plain.json") == root / "real" / "plain.json"
    for name in ("linked-file.json", "linked-folder/secret.json", "pipe.json", "../outside/secret.json"):
        with pytest.raises(HostileMember):
            vet_folder_file(root, name)


# -- every reader applies the same rules -----------------------------------------------------------------------------

def _member(name: str, data: bytes = b"{}") -> tuple[tarfile.TarInfo, bytes]:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    return info, data


@pytest.mark.parametrize("raw", IN_TAR.values(), ids=IN_TAR.keys())
def test_the_model_validator_quarantines_every_hostile_name(raw: str) -> None:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", format=tarfile.PAX_FORMAT) as archive:
        info, data = _member(raw)
        archive.addfile(info, io.BytesIO(data))
    buffer.seek(0)
    report = inspect_archive(buffer)
    assert report.status is ArchiveStatus.QUARANTINED, report.reason


@pytest.mark.parametrize("raw", IN_TAR.values(), ids=IN_TAR.keys())
def test_the_league_reader_skips_every_hostile_name(raw: str, tmp_path: Path) -> None:
    archive = tmp_path / "export.tar.gz"
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", format=tarfile.PAX_FORMAT) as tar:
        for name in (raw, "ip/hyperparameters.json", "model/model_metadata.json"):
            info, data = _member(name, b'{"lr": 1}')
            tar.addfile(info, io.BytesIO(data))
    archive.write_bytes(buffer.getvalue())
    export = read_league_export(archive)
    assert export.names == ["ip/hyperparameters.json", "model/model_metadata.json"]
    assert sorted(export.files) == ["ip/hyperparameters.json", "model/model_metadata.json"]


def test_the_league_reader_still_reads_dot_slash_names(tmp_path: Path) -> None:
    archive = raw_tar_gz(tmp_path / "export.tar.gz", [_member("./model/model_metadata.json"),
                                                      _member("./ip/hyperparameters.json")])
    assert read_league_export(archive).names == ["model/model_metadata.json", "ip/hyperparameters.json"]


def _event_folder(tmp_path: Path, listed: dict[str, bytes]) -> Path:
    folder = tmp_path / "event-export"
    folder.mkdir()
    manifest = {"format": FORMAT, "format_version": FORMAT_VERSION, "event_id": "spring-cup",
                "files": {name: checksums(data) for name, data in listed.items()}}
    (folder / MANIFEST).write_bytes(json_bytes(manifest))
    return folder


@pytest.mark.parametrize("raw", [n for n in HOSTILE_NAMES.values() if "\x00" not in n and "\udcff" not in n],
                         ids=[k for k, n in HOSTILE_NAMES.items() if "\x00" not in n and "\udcff" not in n])
def test_the_event_import_refuses_a_manifest_listing_a_hostile_name(raw: str, tmp_path: Path) -> None:
    folder = _event_folder(tmp_path, {raw: b"{}"})
    with pytest.raises(InvalidExport, match="is not a plain file under a plain relative name"):
        read_event_export(folder)


def test_the_event_import_never_reads_through_a_link(tmp_path: Path) -> None:
    secret = tmp_path / "secret.json"
    secret.write_bytes(b'{"table": "events", "items": []}')
    folder = _event_folder(tmp_path, {"event.json": secret.read_bytes()})  # the checksum of the link's target
    (folder / "event.json").symlink_to(secret)
    with pytest.raises(InvalidExport, match="'event.json' is a symbolic link"):
        read_event_export(folder)


def test_the_event_import_refuses_a_linked_manifest(tmp_path: Path) -> None:
    folder = _event_folder(tmp_path, {})
    real = tmp_path / "elsewhere.json"
    (folder / MANIFEST).rename(real)
    (folder / MANIFEST).symlink_to(real)
    with pytest.raises(InvalidExport, match=r"^manifest\.json is not a plain file"):
        read_event_export(folder)
    assert json.loads(real.read_text())["format"] == FORMAT
