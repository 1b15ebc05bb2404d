"""The installation's storage keys and the state dir's permissions."""
from __future__ import annotations

import os
import stat

import pytest

from drem_local.storage_keys import KEYS_FILE, StorageKeysMissing, load, load_or_create, secure_state_dir

pytestmark = pytest.mark.unit


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_keys_are_drawn_once_kept_0600_and_survive_a_restart(tmp_path):
    state = tmp_path / "state"
    first = load_or_create(state)

    assert load_or_create(state) == first == load(state)
    assert _mode(state) == 0o700 and _mode(state / KEYS_FILE) == 0o600
    assert first.access_key_id.startswith("AKIA") and len(first.secret_access_key) >= 40
    assert first.secret_access_key not in repr(first)
    assert load_or_create(tmp_path / "other") != first, "every installation draws its own keys"


def test_an_older_world_readable_state_dir_is_tightened(tmp_path):
    state = tmp_path / "state"
    (state / "snapshots").mkdir(parents=True)
    for path in (state / "journal.bin", state / "snapshots" / "cognito-idp-1.pickle", state / "stack.json"):
        path.write_bytes(b"passwords inside")
        path.chmod(0o644)
    state.chmod(0o755)

    secure_state_dir(state)

    assert _mode(state) == 0o700 and _mode(state / "snapshots") == 0o700
    assert all(_mode(state / name) == 0o600 for name in ("journal.bin", "stack.json"))
    assert _mode(state / "snapshots" / "cognito-idp-1.pickle") == 0o600


def test_missing_keys_say_how_to_get_them(tmp_path):
    with pytest.raises(StorageKeysMissing, match="drem up --state-dir"):
        load(tmp_path)
    os.makedirs(tmp_path / "broken")
    (tmp_path / "broken" / KEYS_FILE).write_text("{not json")
    with pytest.raises(StorageKeysMissing, match="unreadable"):
        load(tmp_path / "broken")
