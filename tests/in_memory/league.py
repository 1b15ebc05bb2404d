"""The virtual league in memory: the port LeagueService takes.

Copies chalicelib/storage/league.py (DynamoLeagueStore): submissions are kept as their JSON, so a read never hands
out the stored object; `record` stores the submission, its board entry and the evidence claim together or not at all,
and raises EvidenceTaken (storing nothing) when another racer holds the digest; `replace` rewrites only a stored
submission (False when it is gone) and moves the board entry only while it is the racer's latest; `remove_racer`
takes the racer off the board, deletes their history on the track and frees the digests they held, and answers how
many submissions went (at least 1 when only a board entry was left, 0 when there was nothing).
"""
from __future__ import annotations

from chalicelib.domain.league import BoardEntry, EvidenceTaken, LeaguePolicy, Submission
from chalicelib.domain.league_tracks import RegisteredTrack


class InMemoryLeagueStore:
    def __init__(self) -> None:
        self._boards: dict[str, dict[str, str]] = {}  # track -> racer -> the board entry's JSON
        self._history: dict[tuple[str, str, str], str] = {}  # (track, racer, submission id) -> the submission's JSON
        self._evidence: dict[str, str] = {}  # digest -> racer
        self._policies: dict[str, str] = {}  # track -> the policy's JSON
        self._tracks: dict[str, str] = {}  # name -> the registered track's JSON

    def board(self, track: str) -> dict[str, BoardEntry]:
        return {racer: BoardEntry.model_validate_json(entry) for racer, entry in self._boards.get(track, {}).items()}

    def record(self, submission: Submission) -> None:
        digest = submission.evidence_digest or ""
        owner = self._evidence.get(digest)
        if owner is not None and owner != submission.racer:
            raise EvidenceTaken(owner)
        self._history[(submission.track, submission.racer, submission.submission_id)] = submission.model_dump_json()
        self._boards.setdefault(submission.track, {})[submission.racer] = submission.entry().model_dump_json()
        self._evidence[digest] = submission.racer

    def replace(self, submission: Submission) -> bool:
        key = (submission.track, submission.racer, submission.submission_id)
        if key not in self._history:
            return False
        self._history[key] = submission.model_dump_json()
        latest = self.board(submission.track).get(submission.racer)
        if latest is not None and latest.submission_id == submission.submission_id:
            self._boards[submission.track][submission.racer] = submission.entry().model_dump_json()
        return True

    def evidence_owner(self, digest: str) -> str | None:
        return self._evidence.get(digest)

    def policy(self, track: str) -> LeaguePolicy:
        found = self._policies.get(track)
        return LeaguePolicy.model_validate_json(found) if found else LeaguePolicy()

    def set_policy(self, track: str, policy: LeaguePolicy) -> None:
        self._policies[track] = policy.model_dump_json()

    def registered_tracks(self) -> dict[str, RegisteredTrack]:
        return {name: RegisteredTrack.model_validate_json(track) for name, track in self._tracks.items()}

    def register_track(self, name: str, track: RegisteredTrack) -> None:
        self._tracks[name] = track.model_dump_json()

    def submission(self, track: str, racer: str, submission_id: str) -> Submission | None:
        found = self._history.get((track, racer, submission_id))
        return Submission.model_validate_json(found) if found else None

    def remove_racer(self, track: str, racer: str) -> int:
        keys = [key for key in self._history if key[0] == track and key[1] == racer]
        on_board = racer in self._boards.get(track, {})
        if not on_board and not keys:
            return 0
        self._boards.get(track, {}).pop(racer, None)
        for key in keys:
            digest = Submission.model_validate_json(self._history.pop(key)).evidence_digest
            if digest and self._evidence.get(digest) == racer:  # the logs are free again for their real owner
                del self._evidence[digest]
        return max(len(keys), 1)
