"""Accounts and their groups in memory: the port RaceService looks racers up through (RacerDirectory).

Copies chalicelib/storage/users.py (CognitoUserDirectory) on `get_user` and `groups_of`: an unknown name is NotFound
("There is no user '...'", field username, as translate_account_error words Cognito's UserNotFoundException), a user
reads back as a DirectoryUser with their sub, and groups come sorted (an account whose registration never reached its
group has none).
"""
from __future__ import annotations

from chalicelib.core.errors import NotFound
from chalicelib.domain.users import DirectoryUser


class InMemoryUserDirectory:
    def __init__(self) -> None:
        self._users: dict[str, tuple[DirectoryUser, set[str]]] = {}  # username -> (the user, their groups)

    def add(self, username: str, *groups: str) -> DirectoryUser:
        """An account (as the registration desk makes it), in `groups`; its sub is derived from the name."""
        user = DirectoryUser(username=username, sub=f"{username}-sub", email=f"{username}@example.test")
        self._users[username] = (user, set(groups))
        return user

    def get_user(self, username: str) -> DirectoryUser:
        found = self._users.get(username)
        if found is None:
            raise NotFound(f"There is no user '{username}'.", field="username")
        return found[0]

    def groups_of(self, username: str) -> list[str]:
        found = self._users.get(username)
        if found is None:
            raise NotFound(f"There is no user '{username}'.", field="username")
        return sorted(found[1])
