"""The in-memory account directory of the fast domain tier (tests/in_memory/users.py) answers as CognitoUserDirectory
does (over moto) on what RaceService asks it: each assertion here runs against both."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest

from chalicelib.core.errors import NotFound
from tests.in_memory.users import InMemoryUserDirectory

pytestmark = pytest.mark.unit


@dataclass
class Directory:
    port: Any
    add: Callable[..., None]  # add(username, *groups): an account, as the registration desk makes it


@pytest.fixture(params=["in_memory", "cognito"])
def directory(request: pytest.FixtureRequest) -> Directory:
    if request.param == "in_memory":
        memory = InMemoryUserDirectory()
        return Directory(memory, lambda username, *groups: memory.add(username, *groups))
    from chalicelib import services

    users = request.getfixturevalue("users")
    return Directory(services.user_directory(), lambda username, *groups: users.create(username, tuple(groups)))


def test_a_user_reads_back_with_a_sub_and_an_unknown_one_is_not_found(directory: Directory) -> None:
    directory.add("ivy", "racer")
    found = directory.port.get_user("ivy")
    assert found.username == "ivy" and found.sub and found.sub != "ivy"
    with pytest.raises(NotFound, match="There is no user 'nobody'") as refused:
        directory.port.get_user("nobody")
    assert refused.value.field == "username"


def test_groups_come_sorted_and_a_cut_off_registration_has_none(directory: Directory) -> None:
    directory.add("kim", "racer", "commentator")
    directory.add("halfway")
    assert directory.port.groups_of("kim") == ["commentator", "racer"]
    assert directory.port.groups_of("halfway") == []
    with pytest.raises(NotFound):
        directory.port.groups_of("nobody")
