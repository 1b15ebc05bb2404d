"""Issue 27: `drem import` wrote its resume file (temporary passwords) with a plain open, so a file pre-created in a
shared folder received them; export folders and reports were 0644 and hold e-mail addresses."""
from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from chalicelib.formats import private_files
from drem_local.commands.import_ import FileImportJournal, journal_for

pytestmark = pytest.mark.unit


def test_the_resume_file_is_created_0600_and_read_back(tmp_path: Path) -> None:
    journal = journal_for(tmp_path / "export", "ev-1")
    journal.intend("ada", "Temp-Pass-1")
    journal.intend("bob", "Temp-Pass-2")

    assert stat.S_IMODE(journal.path.stat().st_mode) == 0o600
    assert journal.intended() == {"ada": "Temp-Pass-1", "bob": "Temp-Pass-2"}
    assert sorted(p.name for p in tmp_path.iterdir()) == [journal.path.name]  # no temporary file left behind


def test_a_file_planted_at_the_old_temporary_name_receives_nothing(tmp_path: Path) -> None:
    """The old code wrote to `<resume>.tmp` with O_CREAT|O_TRUNC, so a planted world-readable file there (or a link
    to one) got the passwords and was renamed into place keeping its mode."""
    journal = journal_for(tmp_path / "export", "ev-1")
    planted = journal.path.with_name(journal.path.name + ".tmp")
    planted.write_text("")
    planted.chmod(0o666)
    catcher = tmp_path / "catcher"
    catcher.write_text("")
    os.symlink(catcher, tmp_path / "link.tmp")

    journal.intend("ada", "Temp-Pass-1")

    assert planted.read_text() == "" and catcher.read_text() == ""
    assert stat.S_IMODE(journal.path.stat().st_mode) == 0o600


@pytest.mark.parametrize("mode", [0o644, 0o666, 0o660])
def test_a_resume_file_others_may_read_or_change_is_refused_not_trusted(tmp_path: Path, mode: int) -> None:
    """A planted resume file would choose the new accounts' passwords: refused, and nothing is added to it."""
    journal = FileImportJournal(tmp_path / "export.import-ev-1.resume.json")
    journal.path.write_text(json.dumps({"admin2": "Attacker-Knows-1"}))
    journal.path.chmod(mode)

    with pytest.raises(PermissionError, match="remove it and run again"):
        journal.intended()
    with pytest.raises(PermissionError):
        journal.intend("ada", "Temp-Pass-1")
    assert "Temp-Pass-1" not in journal.path.read_text()


def test_a_resume_file_that_is_a_symlink_is_refused(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere.json"
    elsewhere.write_text(json.dumps({"admin2": "Attacker-Knows-1"}))
    elsewhere.chmod(0o600)
    journal = FileImportJournal(tmp_path / "export.import-ev-1.resume.json")
    os.symlink(elsewhere, journal.path)

    with pytest.raises(PermissionError):
        journal.intended()


def test_private_files_refuse_an_existing_name_and_make_folders_0700(tmp_path: Path) -> None:
    folder = tmp_path / "out" / "archives"
    private_files.make_dir(folder)
    private_files.write_new(folder / "a.json", b"{}")

    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) == 0o700
    assert stat.S_IMODE((folder / "a.json").stat().st_mode) == 0o600
    with pytest.raises(FileExistsError):
        private_files.write_new(folder / "a.json", b"again")
