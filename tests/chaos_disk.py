"""The chaos bench's disk-full round: a stack whose state dir is on a small tmpfs (mounted here; root only), filled to
the last byte while the desk registers racers and files are stored; then a power cut (kill -9 of every process), space
freed, and a restart.

Every write is answered either as stored (the journal's preallocated room takes it) or with 507 and the words
"drem's data disk is full at <path>" (nothing of it acknowledged). After the restart everything acknowledged is there
with the identity it was given (a racer's `sub`), and nothing refused is half made: a refused registration is either
absent or a whole account with its racer group.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drem_local.stack import StackConfig, free_port, start_stack
from drem_local.storage_keys import load, local_client
from tests.chaos_harness import ADMIN_PASSWORD, Api

OBJECT_BYTES = 256 * 1024
FULL_WORDS = "drem's data disk is full at"


@dataclass
class DiskFullFigures:
    acknowledged: int = 0  # registrations and stored files answered as stored while the disk was full
    refused: int = 0  # answered 507 with the words
    lost: int = 0
    changed_identity: int = 0
    half: int = 0
    wordless_refusals: list[str] = field(default_factory=list)  # a refusal that did not say the disk is full
    skipped: str = ""  # why the round could not run here

    @property
    def clean(self) -> bool:
        return not self.skipped and self.refused > 0 and self.lost == self.changed_identity == self.half == 0 \
            and not self.wordless_refusals

    def line(self) -> str:
        if self.skipped:
            return f"skipped ({self.skipped})"
        return (f"{self.acknowledged} ack/{self.refused} refused 507/{self.lost} lost/{self.changed_identity} "
                f"redrawn/{self.half} half")


def mount_small_disk(where: Path, size: str = "96m") -> str | None:
    """A tmpfs of `size` at `where`; None when mounted, else why not."""
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0700", "tmpfs", str(where)],
                          capture_output=True, text=True)
    return None if done.returncode == 0 else f"mount failed: {done.stderr.strip()}"


def unmount(where: Path) -> None:
    subprocess.run(["umount", "-l", str(where)], check=False, capture_output=True)


def fill(disk: Path) -> Path:
    """Write a file until the disk refuses another byte."""
    filler = disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        for chunk in (1 << 20, 1 << 12, 1):
            try:
                while os.write(fd, b"\xff" * chunk):
                    pass
            except OSError:
                pass
    finally:
        os.close(fd)
    return filler


def disk_full_round(work: Path, say: Any = print) -> DiskFullFigures:
    figures = DiskFullFigures()
    disk = work / "small-disk"
    why_not = mount_small_disk(disk)
    if why_not:
        figures.skipped = why_not
        return figures
    try:
        _run(disk, figures, say)
    finally:
        unmount(disk)
    return figures


def _run(disk: Path, figures: DiskFullFigures, say: Any) -> None:
    state_dir = disk / "state"
    config = StackConfig(state_dir=state_dir, app_port=free_port(), storage_port=free_port(), live_port=free_port(),
                         snapshot_interval=0.5)
    running = start_stack(config, "admin", ADMIN_PASSWORD, timeout=120)
    filler: Path | None = None
    try:
        api = Api(config.app_url)
        api.login("admin", ADMIN_PASSWORD)
        s3 = local_client("s3", config.storage_url, load(state_dir))
        s3.create_bucket(Bucket="disk-round")
        filler = fill(disk)
        say(f"disk at {disk} filled; writing until the journal's room is used up")
        racers: dict[str, str] = {}  # acknowledged → sub
        refused_racers: list[str] = []
        objects: dict[str, str] = {}  # acknowledged key → md5
        for number in range(200):  # the room is 4 MiB: 16 files of 256 KiB and it is gone
            username = f"disk-racer-{number}"
            answer = api.call("POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                     "country_code": "DE"})
            if answer is not None and answer[0] == 201:
                racers[username] = answer[1]["sub"]
            elif answer is not None and answer[0] == 507:
                refused_racers.append(username)
                _note_words(figures, answer[1])
            else:
                figures.wordless_refusals.append(f"registration answered {answer}"[:300])
            key, body = f"file-{number}", os.urandom(OBJECT_BYTES)
            try:
                s3.put_object(Bucket="disk-round", Key=key, Body=body)
                objects[key] = hashlib.md5(body).hexdigest()
            except Exception as exc:  # botocore's ClientError: 507 with the storage server's words
                response = getattr(exc, "response", {}) or {}
                if response.get("ResponseMetadata", {}).get("HTTPStatusCode") == 507:
                    figures.refused += 1
                    _note_words(figures, {"error": {"message": response.get("Error", {}).get("Message", "")}})
                else:
                    figures.wordless_refusals.append(f"file {key}: {exc}"[:300])
            if len(refused_racers) >= 3:
                break
        figures.refused += len(refused_racers)
        figures.acknowledged = len(racers) + len(objects)
        say(f"{len(racers)} racers and {len(objects)} files acknowledged, {figures.refused} writes refused with "
            f"507; power cut, space freed, restart")
        for process in (running.scrutineer, running.trainer, running.app, running.live, running.storage):
            if process is not None:
                process.kill_hard()
        filler.unlink()
        running.restart_storage(120)
        running.restart_app(120)
        api.login("admin", ADMIN_PASSWORD)
        users = {u["username"]: u for u in _users(api)}
        for username, sub in racers.items():
            if username not in users:
                figures.lost += 1
            elif users[username]["sub"] != sub:
                figures.changed_identity += 1
            elif "racer" not in _groups(api, username):
                figures.half += 1
        for key, md5 in objects.items():
            try:
                stored = hashlib.md5(s3.get_object(Bucket="disk-round", Key=key)["Body"].read()).hexdigest()
            except Exception:
                stored = ""
            figures.lost += stored != md5
        deadline = time.monotonic() + 60  # a refused registration: absent, or whole once the repair sweep ran
        half = [name for name in refused_racers if name in users]
        while half and time.monotonic() < deadline:
            half = [name for name in half if "racer" not in _groups(api, name)]
            time.sleep(1)
        figures.half += len(half)
    finally:
        if filler is not None:
            filler.unlink(missing_ok=True)
        running.stop()


def _note_words(figures: DiskFullFigures, body: Any) -> None:
    message = body.get("error", {}).get("message", "") if isinstance(body, dict) else str(body)
    if FULL_WORDS not in message:
        figures.wordless_refusals.append(message[:300])


def _users(api: Api) -> list[dict[str, Any]]:
    users: list[dict[str, Any]] = []
    token = None
    while True:
        page = api.until_answered("GET", "/api/users?limit=60" + (f"&next={token}" if token else ""))
        users += page["users"]
        token = page.get("next_token")
        if not token:
            return users


def _groups(api: Api, username: str) -> list[str]:
    reply = api.until_answered("GET", f"/api/users/{username}/groups")
    return reply.get("groups", []) if isinstance(reply, dict) else reply
