"""Verified entries: a push that brings the racer's model is queued for drem's re-drive on the board's track, and
the board then ranks what drem measured, marked "verified by drem"; logs claiming laps more than LOG_MARGIN faster
than that re-drive are not believed; each league's organiser chooses what happens to self-reported entries.

In process over moto (the model uploaded as `drem models upload` stores it); the drive itself is a stand-in here
(the real bounded simulator drive by track name is tests/sim/test_scrutineer_worker_drive.py)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from chalicelib import services
from chalicelib.core.errors import Forbidden, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.league import BoardQuery, LeaguePolicy, SelfReported
from chalicelib.domain.league_intake import LeagueVerifier, PushOptions
from chalicelib.domain.model_scrutiny import DriveOutcome
from chalicelib.domain.racer_models import ModelRecord, ScrutineerResult, UploadRequest
from chalicelib.formats.league_export import pack_exports, read_export
from tests.unit.league_helpers import console_old_export, drem_sim_export
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))
BOB = User(sub="sub-bob", username="bob", groups=frozenset({"racer"}))
ADMIN = User(sub="sub-root", username="root", groups=frozenset({"admin"}))
TRACK = "reinvent_base"


def upload_model(stack: Any, aws_clients: Any, owner: User, bias: float = 0.0) -> ModelRecord:
    service = services.model_service()
    ticket = service.request_upload(owner, UploadRequest(filename=f"{owner.username}-bc.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive(bias))
    return service.complete(owner, ticket.model.model_id)


def report(best: float | None, completed: int = 3) -> ScrutineerResult:
    return ScrutineerResult(verdict="passed" if completed else "failed", track=TRACK, track_type="LEAGUE", laps=3,
                            laps_completed=completed, best_lap_time_s=best,
                            mean_lap_time_s=best + 0.4 if best else None, offtrack_count=3 - completed,
                            message=f"{completed}/3 laps completed on {TRACK}")


class FakeDrive:
    def __init__(self, outcome: DriveOutcome) -> None:
        self.outcome = outcome
        self.calls: list[tuple[str, set[str]]] = []

    def __call__(self, folder: Path, track: str, laps: int) -> DriveOutcome:
        self.calls.append((track, {p.name for p in folder.iterdir()}))
        return self.outcome


def verifier(drive: FakeDrive) -> LeagueVerifier:
    queue = services.league_verify_queue()
    assert queue is not None
    return LeagueVerifier(services.league_service(), services.scrutineer_service(), queue, drive)


def board(**query: Any) -> list[Any]:
    return [ranked.entry for ranked in services.league_service().board(TRACK, BoardQuery(**query)).entries]


def push(principal: User, folder: Path, model: ModelRecord | None = None) -> Any:
    upload = pack_exports([read_export(folder)])
    return services.league_intake().push_upload(principal, TRACK, upload, PushOptions(
        model_id=model.model_id if model else None, model_name=folder.name))


def test_a_pushed_model_is_re_driven_and_ranked_on_what_drem_measured(stack: Any, aws_clients: Any,
                                                                      tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    logs = drem_sim_export(tmp_path / "alice-bc", track=TRACK, progress=[100, 100], lap_times=[15.0, 15.2])
    pending = push(ALICE, logs, model)
    assert pending.verification == "pending" and pending.model_id == model.model_id
    assert board()[0].source == "self-reported from logs"

    drive = FakeDrive(DriveOutcome(reports=[report(16.1)]))
    verified = verifier(drive).run_one()
    assert drive.calls == [(TRACK, {"model.onnx", "model_metadata.json"})]
    assert verified is not None and verified is not False and verified.verification == "verified"
    entry = board()[0]
    assert entry.source == "verified by drem"
    assert (entry.best_lap_s, entry.average_lap_s, entry.laps_completed) == (16.1, 16.5, 3)  # drem's, not the logs'
    assert verifier(drive).run_one() is False  # the queue is empty


def test_a_verified_entry_shows_the_completion_scrutineering_measured(stack: Any, aws_clients: Any,
                                                                     tmp_path: Path) -> None:
    """A model that leaves the track at the same bend on every lap: the board's completion for drem's re-drive is the
    scrutineering figure of that drive (mean progress per lap attempt), as a self-reported trial's is, not the share
    of laps completed (0 %, which would rank it with a car that never left the line)."""
    model = upload_model(stack, aws_clients, ALICE)
    push(ALICE, drem_sim_export(tmp_path / "m", track=TRACK, progress=[60.0], lap_times=[]), model)
    three_bends = report(None, completed=0).model_copy(update={"attempts": 3, "completion_pct": 62.4})
    verifier(FakeDrive(DriveOutcome(reports=[three_bends]))).run_one()

    entry = board()[0]
    assert entry.source == "verified by drem"
    assert (entry.laps_completed, entry.trials, entry.average_completion_pct) == (0, 3, 62.4)


def test_logs_much_faster_than_drems_re_drive_are_not_believed(stack: Any, aws_clients: Any, tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    logs = drem_sim_export(tmp_path / "edited", track=TRACK, progress=[100], lap_times=[9.5])  # edited down
    push(ALICE, logs, model)
    disputed = verifier(FakeDrive(DriveOutcome(reports=[report(16.1)]))).run_one()
    assert disputed is not None and disputed is not False and disputed.verification == "disputed"
    assert "claim a 9.500 s lap, but drem measured 16.100 s" in disputed.verification_note
    assert board() == []
    assert services.league_service().latest(TRACK, "alice").verification == "disputed"


def test_a_model_that_cannot_be_re_driven_stays_self_reported(stack: Any, aws_clients: Any, tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    push(ALICE, drem_sim_export(tmp_path / "m", track=TRACK, progress=[100], lap_times=[15.0]), model)
    result = verifier(FakeDrive(DriveOutcome(failure="The test drive took longer than 90 s"))).run_one()
    assert result is not None and result is not False and result.verification == "not_verified"
    entry = board()[0]
    assert entry.source == "self-reported from logs" and entry.best_lap_s == 15.0


def test_console_logs_take_the_metadata_of_the_pushed_model(stack: Any, aws_clients: Any, tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    logs = console_old_export(tmp_path / "console-logs", world=TRACK, laps=[(15000, 100)])
    (logs / "model/model_metadata.json").unlink()
    submission = push(ALICE, logs, model)
    assert submission.action_space == "continuous, steering -30..30 deg, speed 0.5..2 m/s"  # the model's own


def test_a_racer_cannot_push_another_racers_model(stack: Any, aws_clients: Any, tmp_path: Path) -> None:
    alices = upload_model(stack, aws_clients, ALICE)
    with pytest.raises((NotFound, Forbidden)):
        push(BOB, drem_sim_export(tmp_path / "m", track=TRACK, progress=[100], lap_times=[15.0]), alices)
    assert board() == []


def test_the_organiser_chooses_what_happens_to_self_reported_entries(stack: Any, aws_clients: Any,
                                                                     tmp_path: Path) -> None:
    league = services.league_service()
    bobs = drem_sim_export(tmp_path / "bob", track=TRACK, progress=[100], lap_times=[12.0])  # fast, logs only
    push(BOB, bobs)
    model = upload_model(stack, aws_clients, ALICE)
    push(ALICE, drem_sim_export(tmp_path / "alice", track=TRACK, progress=[100], lap_times=[15.0]), model)
    verifier(FakeDrive(DriveOutcome(reports=[report(15.3)]))).run_one()

    assert [e.racer for e in board()] == ["bob", "alice"]  # default: shown, ranked together
    with pytest.raises(Forbidden):
        league.set_policy(ALICE, TRACK, LeaguePolicy(self_reported=SelfReported.REFUSED))
    league.set_policy(ADMIN, TRACK, LeaguePolicy(self_reported=SelfReported.BELOW_VERIFIED))
    assert [(e.racer, e.source) for e in board()] == [("alice", "verified by drem"), ("bob", "self-reported from logs")]
    league.set_policy(ADMIN, TRACK, LeaguePolicy(self_reported=SelfReported.REFUSED))
    assert [e.racer for e in board()] == ["alice"]
    with pytest.raises(Forbidden, match="takes only entries drem verifies"):
        push(BOB, drem_sim_export(tmp_path / "bob2", track=TRACK, progress=[100], lap_times=[12.5]))


def test_a_re_drive_interrupted_by_the_workers_stop_is_given_back_at_once(stack: Any, aws_clients: Any,
                                                                          tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    push(ALICE, drem_sim_export(tmp_path / "m", track=TRACK, progress=[100], lap_times=[15.0]), model)

    class Stopped(BaseException):
        pass

    def stopped_mid_drive(folder: Path, track: str, laps: int) -> DriveOutcome:
        raise Stopped  # SIGTERM while the child drives

    interrupted = verifier(FakeDrive(DriveOutcome()))
    interrupted.drive = stopped_mid_drive
    with pytest.raises(Stopped):
        interrupted.run_one()
    interrupted.give_back()
    job = interrupted.queue.state_of(model.model_id)
    assert job is not None and job.state == "queued"  # not leased for minutes: the next start drives it
    assert verifier(FakeDrive(DriveOutcome(reports=[report(16.0)]))).run_one() is not False
    assert board()[0].source == "verified by drem"


def test_a_model_deleted_before_its_re_drive_leaves_the_entry_self_reported(stack: Any, aws_clients: Any,
                                                                           tmp_path: Path) -> None:
    model = upload_model(stack, aws_clients, ALICE)
    push(ALICE, drem_sim_export(tmp_path / "m", track=TRACK, progress=[100], lap_times=[15.0]), model)
    services.model_service().delete(ALICE, model.model_id)
    drive = FakeDrive(DriveOutcome(reports=[report(16.0)]))
    result = verifier(drive).run_one()
    assert drive.calls == []  # nothing driven
    assert result is not None and result is not False and result.verification == "not_verified"
    assert "deleted before drem re-drove it" in result.verification_note
    assert board()[0].source == "self-reported from logs"
