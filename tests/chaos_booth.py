"""The booth-training round of the chaos operations (tests/chaos_operations.py): a visitor's drive, Train pressed, and
the trainer worker (`python -m drem_local.workers.trainer`, started and restarted by `drem up`'s Supervisor) training,
exporting, checking and registering the visitor's next version, scrutineering it and driving its autonomous run.

Each round is a new visitor (an account the desk registers, a password, a sign-in), so "exactly one new version" is
simply the visitor's models. Their drive is a short manual drive of `drem_oval` (DRIVE_FRAMES frames, recorded once
per campaign with the simulator's demonstrator at a visitor's pace) that goes in through the booth's artifact API as
the live drive stores it: a run, its frames and controls PUT, finalised. Then the kill point is armed and the visitor
presses Train (the booth form, with the form's own Epochs field at 1: training shortened the way a visitor can,
producing the same kind of model), again if the page gave no answer, and waits until the job ends.

After the restart the round checks what the visitor would notice: one job (not 0, not 2), DONE (FAILED counts as a
lost version, with its reason; still QUEUED/RUNNING after the deadline counts as stuck), exactly one model, the job's,
AVAILABLE, with its archive in the models bucket and no archive or upload left without its record, one FINALISED
autonomous run for the job, and pressing Train again does not make a second job or version.
"""
from __future__ import annotations

import re
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import requests

from tests.chaos_harness import RETRYABLE, Api

if TYPE_CHECKING:
    from tests.chaos_operations import OperationKills

TRACK = "drem_oval"
DRIVE_FRAMES = 300  # ~20 s of driving at 15 frames a second: a short drive, a few seconds of training
EPOCHS = 1  # the Train form's Epochs field (1..30)
JOB_DEADLINE_S = 300.0  # a restarted trainer imports PyTorch again; on a loaded 2-core machine that takes a while
VISITOR_PASSWORD = "Chaos-Visitor-Pass-1!"
OPERATION = "booth training"


class BoothTraining:
    def __init__(self, kills: OperationKills) -> None:
        self.kills = kills
        self._drive: Path | None = None

    # --- setup: the trainer worker and the recorded drive -------------------------------------------------------------

    def _setup(self) -> None:
        stack = self.kills.stack
        if stack.trainer is None:  # `drem up` runs it; the traffic rounds do not need it, so it starts here
            with self.kills._checking:
                stack.restart_trainer()
        if self._drive is None:
            self._drive = _record_drive(self.kills.work_dir / "booth-drive")

    def _visitor(self) -> tuple[Api, str]:
        from drem_local.stack import REGION
        from drem_local.storage_keys import load, local_client

        kills = self.kills
        username = kills._name("visitor")
        kills.api.until_answered("POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                        "country_code": "DE"}, ok=(201,))
        cognito = local_client("cognito-idp", kills.stack.config.storage_url, load(kills.stack.config.state_dir),
                               REGION)
        cognito.admin_set_user_password(UserPoolId=kills.stack.outputs.user_pool_id, Username=username,
                                        Password=VISITOR_PASSWORD, Permanent=True)
        visitor = Api(kills.stack.config.app_url)
        visitor.login(username, VISITOR_PASSWORD)
        return visitor, username

    def _upload_drive(self, visitor: Api) -> str:
        """The drive through the booth's artifact API, as the live drive stores it; each step repeated until answered
        (a PUT of the same bytes again is harmless)."""
        from drem_sim.runs import pack_frames

        assert self._drive is not None
        run = visitor.until_answered("POST", "/api/runs", {"track_id": TRACK, "mode": "manual"}, ok=(201,))["run"]
        for name, data in (("frames.tar", pack_frames(self._drive)),
                           ("controls.jsonl", (self._drive / "controls.jsonl").read_bytes())):
            _put_until_answered(visitor, f"/api/runs/{run['run_id']}/artifacts/{name}", data)
        visitor.until_answered("POST", f"/api/runs/{run['run_id']}/finalise", ok=(200,))
        return str(run["run_id"])

    # --- the round ----------------------------------------------------------------------------------------------------

    def run(self, arm_for: Any) -> dict[str, Any]:
        self._setup()
        visitor, username = self._visitor()
        run_id = self._upload_drive(visitor)
        trainer = self.kills.stack.trainer
        arm_for(trainer.pid if trainer is not None else None)
        pressed = self._press_train(visitor)
        jobs = self._settled_jobs(visitor)
        return {"visitor": visitor, "username": username, "run_id": run_id, "pressed": pressed, "jobs": jobs}

    def _press_train(self, visitor: Api) -> list[int]:
        """Train, again while the page gives no answer; the answers seen (a 409 'already in the queue' or 'nothing
        changed' after a first press that was stored is what the visitor then reads)."""
        answers: list[int] = []
        deadline = time.monotonic() + JOB_DEADLINE_S
        while time.monotonic() < deadline:
            answer = _form(visitor, "/booth/train", {"epochs": str(EPOCHS)})
            if answer is not None:
                answers.append(answer[0])
                if answer[0] not in RETRYABLE:
                    if answer[0] not in (200, 409):
                        self.kills._problem(OPERATION, f"Train answered {answer[0]}: {_text(answer[1])[:200]}")
                    return answers
            time.sleep(0.5)
        self.kills._problem(OPERATION, "Train never answered")
        return answers

    def _settled_jobs(self, visitor: Api) -> list[dict[str, Any]]:
        """The visitor's jobs once none is queued or running (or as they are at the deadline: stuck)."""
        deadline = time.monotonic() + JOB_DEADLINE_S
        jobs: list[dict[str, Any]] = []
        while time.monotonic() < deadline:
            answer = visitor.call("GET", "/api/training-jobs")
            if answer is not None and answer[0] == 200:
                jobs = answer[1]["jobs"]
                if jobs and all(job["status"] in ("DONE", "FAILED") for job in jobs):
                    return jobs
            time.sleep(0.5)
        return jobs

    # --- the verdict --------------------------------------------------------------------------------------------------

    def check(self, outcome: dict[str, Any]) -> None:
        kills = self.kills
        figures = kills.figures[OPERATION]
        visitor, username, jobs = outcome["visitor"], outcome["username"], outcome["jobs"]
        figures.acknowledged += 1
        if not jobs:
            figures.lost += 1
            kills._problem(OPERATION, f"{username}: Train was pressed ({outcome['pressed']}) and no job exists")
            return
        figures.duplicated += len(jobs) - 1
        job = jobs[0]
        if job["status"] not in ("DONE", "FAILED"):
            figures.half += 1
            kills._problem(OPERATION, f"{username}: job {job['job_id']} still {job['status']} ({job['stage']}) "
                                      f"{JOB_DEADLINE_S:.0f}s after Train")
            return
        if job["status"] == "FAILED":
            figures.lost += 1
            kills._problem(OPERATION, f"{username}: job {job['job_id']} FAILED: {job['reason']}")
        models = visitor.until_answered("GET", "/api/models?limit=100")["models"]
        figures.duplicated += max(0, len(models) - 1)
        if job["status"] == "DONE":
            mine = [m for m in models if m["model_id"] == job["model_id"]]
            if not mine:
                figures.lost += 1
                kills._problem(OPERATION, f"{username}: job {job['job_id']} DONE but its {job['model_name']} is gone")
            elif mine[0]["status"] != "AVAILABLE" or mine[0]["name"] != job["model_name"]:
                figures.half += 1
                kills._problem(OPERATION, f"{username}: the job's version is {mine[0]['name']} "
                                          f"{mine[0]['status']} ({mine[0].get('reason')})")
        if len(models) > 1:
            kills._problem(OPERATION, f"{username}: {len(models)} versions: "
                                      f"{[(m['name'], m['status'], m.get('reason')) for m in models]}")
        self._check_archives(username, models)
        self._check_autonomous_run(visitor, username, job)
        if job["status"] == "DONE":  # (after a failure, Train again rightly queues a new job)
            self._check_train_again(visitor, username)

    def _check_archives(self, username: str, models: list[dict[str, Any]]) -> None:
        """No model record without its archive, no archive (or upload) without its record."""
        from drem_local.stack import REGION
        from drem_local.storage_keys import load, local_client

        kills = self.kills
        figures = kills.figures[OPERATION]
        owner = models[0]["owner_sub"] if models else None
        if owner is None:
            return
        s3 = local_client("s3", kills.stack.config.storage_url, load(kills.stack.config.state_dir), REGION)
        bucket = kills.stack.outputs.buckets["models"]
        keys = set()
        for prefix in (f"models/{owner}/", f"uploads/{owner}/", f"quarantine/{owner}/"):
            listing = s3.list_objects_v2(Bucket=bucket, Prefix=prefix)
            keys |= {item["Key"] for item in listing.get("Contents", [])}
        available = {m["model_id"] for m in models if m["status"] == "AVAILABLE"}
        for model_id in available:
            if f"models/{owner}/{model_id}.tar.gz" not in keys:
                figures.half += 1
                kills._problem(OPERATION, f"{username}: model {model_id} is AVAILABLE without its archive")
        for key in sorted(keys):
            match = re.fullmatch(r"(models|uploads)/[^/]+/([0-9a-f]+)\.tar\.gz", key)
            if match and (match.group(1) == "uploads" or match.group(2) not in available):
                figures.half += 1
                kills._problem(OPERATION, f"{username}: {key} is stored without an AVAILABLE model record")

    def _check_autonomous_run(self, visitor: Api, username: str, job: dict[str, Any]) -> None:
        kills = self.kills
        figures = kills.figures[OPERATION]
        runs = visitor.until_answered("GET", "/api/runs")["runs"]
        of_job = [r for r in runs if r.get("job_id") == job["job_id"]]
        figures.duplicated += max(0, len(of_job) - 1)
        if job["status"] == "DONE" and [(r["run_id"], r["status"]) for r in of_job] != \
                [(job["autonomous_run_id"], "FINALISED")]:
            figures.half += 1
            kills._problem(OPERATION, f"{username}: the job's autonomous run {job['autonomous_run_id']} vs "
                                      f"{[(r['run_id'], r['status']) for r in of_job]}")

    def _check_train_again(self, visitor: Api, username: str) -> None:
        """The visitor presses Train again on the same drive: refused in words, nothing new queued."""
        kills = self.kills
        before = visitor.until_answered("GET", "/api/training-jobs")["jobs"]
        answer = None
        while answer is None or answer[0] in RETRYABLE:
            answer = _form(visitor, "/booth/train", {"epochs": str(EPOCHS)})
        after = visitor.until_answered("GET", "/api/training-jobs")["jobs"]
        if len(after) != len(before):
            kills.figures[OPERATION].duplicated += len(after) - len(before)
            kills._problem(OPERATION, f"{username}: Train pressed again queued a second job ({answer[0]})")


def _record_drive(folder: Path) -> Path:
    """A visitor's short manual drive (repeatable: the demonstrator at a visitor's pace with steering noise)."""
    import numpy as np

    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import RaceEnv
    from drem_sim.runs import record_run
    from drem_sim.tracks import load_track

    track = load_track(TRACK)
    teacher = Demonstrator(track, DemonstratorConfig(max_speed=0.55, min_speed=0.35, steering_noise_deg=3.0),
                           rng=np.random.default_rng(1))
    return record_run(RaceEnv(track), lambda _obs, params: teacher.act(params), folder, laps=100, driver="chaos",
                      max_steps=DRIVE_FRAMES)


def _form(api: Api, path: str, form: dict[str, str]) -> tuple[int, str] | None:
    """A booth form posted the way htmx posts it (None: no answer)."""
    try:
        reply = api.http.post(api.url + path, data=form, timeout=30, headers={
            "Authorization": f"Bearer {api.token}", "HX-Request": "true"})
    except requests.RequestException:
        return None
    return reply.status_code, reply.text


def _put_until_answered(api: Api, path: str, data: bytes) -> None:
    deadline = time.monotonic() + JOB_DEADLINE_S
    while time.monotonic() < deadline:
        try:
            reply = api.http.put(api.url + path, data=data, timeout=60, headers={
                "Authorization": f"Bearer {api.token}", "Content-Type": "application/octet-stream",
                "Accept": "application/json"})
            if reply.status_code in (200, 201, 204):
                return
            if reply.status_code not in RETRYABLE:
                raise RuntimeError(f"PUT {path} answered {reply.status_code}: {reply.text[:200]}")
        except requests.RequestException:
            pass
        time.sleep(0.5)
    raise RuntimeError(f"PUT {path} never answered")


def _text(html: str) -> str:
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).strip()
