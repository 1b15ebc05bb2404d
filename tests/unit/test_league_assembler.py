"""The assembler reads each real export layout (folder and .tar.gz) into one submission, and says which file and
field is wrong when it cannot."""
from __future__ import annotations

import json
import tarfile
from pathlib import Path

import pytest

from chalicelib.core.errors import InvalidInput, PayloadTooLarge
from chalicelib.domain.league_assembler import ExportProblem, assemble
from chalicelib.domain.league_tracks import DREM_TRACK_LENGTHS_M
from chalicelib.formats.league_export import ExportLimits, read_export
from tests.unit.league_helpers import (
    CONTINUOUS_SAC_METADATA,
    HYPERPARAMETERS,
    console_log,
    console_new_export,
    console_old_export,
    drem_sim_export,
    drfc_export,
    droa_export,
    raw_tar_gz,
    simtrace,
    tar_gz_of,
    training_metrics,
)

pytestmark = pytest.mark.unit

LAPS = [(16468, 100), (16267, 100), (9000, 54)]


def build(path: Path, track: str = "reinvent_base", **options):
    return assemble(read_export(path), racer="alice", track=track, track_length_m=DREM_TRACK_LENGTHS_M[track],
                    **options)


def test_old_console_export(tmp_path: Path) -> None:
    submission = build(console_old_export(tmp_path / "alice-model", world="reinvent_base", laps=LAPS))
    assert submission.layout == "console-old"
    assert submission.model_name == "alice-model"
    assert submission.algorithm == "clipped_ppo" and submission.sensor == ["FRONT_FACING_CAMERA"]
    assert submission.action_space == "10 discrete actions, steering -30..30 deg, speed 1..2 m/s"
    assert submission.hyperparameters == HYPERPARAMETERS
    assert submission.training_track == "reinvent_base"  # read from the robomaker log's params
    assert (submission.training_episodes, submission.training_best_completion_pct) == (4, 100.0)
    assert [(t.time_s, t.completion_pct, t.off_track_count, t.reset_count) for t in submission.trials] == [
        (16.468, 100.0, 0, 0), (16.267, 100.0, 0, 0), (9.0, 54.0, 1, 1)]


def test_new_console_export_with_iso_folders(tmp_path: Path) -> None:
    submission = build(console_new_export(tmp_path / "m", world="reinvent_base", laps=[(20000, 100)]))
    assert submission.layout == "console-new"
    assert submission.training_episodes == 3 and submission.trials[0].time_s == 20.0


def test_drfc_prefix_uses_the_newest_evaluation(tmp_path: Path) -> None:
    submission = build(drfc_export(tmp_path / "rl-deepracer-sagemaker", world="reinvent_base", laps=LAPS))
    assert submission.layout == "drfc"
    assert submission.algorithm == "sac" and submission.sensor == ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"]
    assert submission.action_space == "continuous, steering -30..30 deg, speed 1..2 m/s"
    assert submission.hyperparameters["sac_alpha"] == 0.2
    assert [t.time_s for t in submission.trials] == [16.468, 16.267, 9.0]  # not the older 99 s file
    assert (submission.training_episodes, submission.training_best_completion_pct) == (5, 100.0)


def test_drem_sim_run(tmp_path: Path) -> None:
    submission = build(drem_sim_export(tmp_path / "bc-1", track="reinvent_base", progress=[100, 37.5, 100],
                                       lap_times=[21.5, 20.25]))
    assert submission.layout == "drem-sim" and submission.algorithm == "behaviour_cloning"
    assert submission.hyperparameters["learning_rate"] == 0.001 and submission.training_episodes == 10
    assert submission.training_best_completion_pct is None and submission.training_track == "reinvent_base"
    assert [(t.time_s, t.completion_pct, t.off_track_count) for t in submission.trials] == [
        (21.5, 100.0, 0), (0.0, 37.5, 1), (20.25, 100.0, 0)]


@pytest.mark.parametrize("top", [None, "my-export"])
def test_tar_gz_matches_the_folder(tmp_path: Path, top: str | None) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    archive = tar_gz_of(folder, tmp_path / "m.tar.gz", top=top)
    from_archive = build(archive)
    assert from_archive.model_dump(exclude={"model_name"}) == build(folder).model_dump(exclude={"model_name"})
    assert from_archive.model_name == (top or "m")


def _problem(path: Path, track: str = "reinvent_base") -> str:
    with pytest.raises(ExportProblem) as caught:
        build(path, track)
    return caught.value.message


def test_missing_hyperparameters(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    (folder / "ip/hyperparameters.json").unlink()
    assert _problem(folder).startswith("ip/hyperparameters.json: missing")


def test_invalid_json_in_evaluation_metrics(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    (folder / "metrics/EvaluationMetrics-20240102030405.json").write_text('{"metrics": [ {"trial": 1,,}]}')
    message = _problem(folder)
    assert message.startswith("metrics/EvaluationMetrics-20240102030405.json: is not valid JSON")
    assert "line 1" in message


def test_yaml_without_world_name(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    (folder / "training_params.yaml").write_text("JOB_TYPE: TRAINING\nRACE_TYPE: TIME_TRIAL\n")
    assert _problem(folder) == "training_params.yaml: WORLD_NAME: missing or not a track name"


def test_evaluation_on_another_track(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS, eval_world="Spain_track")
    assert "evaluation_params.yaml: WORLD_NAME: the evaluation ran on 'Spain_track'" in _problem(folder)


def test_evaluation_entry_without_lap_time(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    path = next((folder / "metrics/evaluation").glob("*.json"))
    document = json.loads(path.read_text())
    del document["metrics"][1]["elapsed_time_in_milliseconds"]
    path.write_text(json.dumps(document))
    assert _problem(folder).endswith(": metrics[1].elapsed_time_in_milliseconds: missing")


def test_bad_model_metadata_names_the_field(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS,
                                metadata={"action_space": [{"steering_angle": 45, "speed": 1.0}],
                                          "sensor": ["FRONT_FACING_CAMERA"]})
    message = _problem(folder)
    assert message.startswith("model/model_metadata.json: action_space[0].steering_angle")


def test_console_export_without_any_track_source(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    for log in (folder / "logs/training").glob("*robomaker.log"):
        log.unlink()
    assert build(folder).training_track is None  # the training track is shown, never needed
    for trace in folder.rglob("evaluation-simtrace/*.csv"):
        trace.unlink()
    message = _problem(folder)
    assert message.startswith(f"metrics/evaluation/{CONSOLE_EVALUATION}.json: nothing in the export says which track")
    assert "logs/evaluation/*-robomaker.log" in message and "evaluation-simtrace/0-iteration.csv" in message


def test_empty_training_metrics(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    (folder / "metrics/TrainingMetrics.json").write_text('{"metrics": [], "version": 2.0}')
    assert _problem(folder) == "metrics/TrainingMetrics.json: metrics: missing or empty (no episodes recorded)"


def test_drem_metrics_for_another_track(tmp_path: Path) -> None:
    folder = drem_sim_export(tmp_path / "bc", track="Spain_track", progress=[100], lap_times=[20.0])
    assert _problem(folder) == "metrics.json: track: the evaluation ran on 'Spain_track', not on 'reinvent_base'"


# -- hostile archives ------------------------------------------------------------------------------------------------

def _member(name: str, data: bytes | None = b"{}", kind: bytes = tarfile.REGTYPE, link: str = "") -> tuple:
    info = tarfile.TarInfo(name)
    info.type, info.linkname = kind, link
    info.size = len(data) if data is not None and kind == tarfile.REGTYPE else 0
    return info, data if kind == tarfile.REGTYPE else None


def test_archive_links_and_escaping_names_are_never_read(tmp_path: Path) -> None:
    archive = raw_tar_gz(tmp_path / "evil.tar.gz", [
        _member("../../etc/hyperparameters.json", b'{"lr": 1}'),
        _member("/abs/hyperparameters.json", b'{"lr": 1}'),
        _member("ip/hyperparameters.json", kind=tarfile.SYMTYPE, link="/etc/passwd"),
        _member("model/model_metadata.json", kind=tarfile.LNKTYPE, link="../../secret.json"),
    ])
    export = read_export(archive)
    assert export.files == {} and export.names == []
    assert not (tmp_path.parent / "etc").exists()
    with pytest.raises(ExportProblem, match="model/model_metadata.json: missing"):
        assemble(export, racer="alice", track="reinvent_base", track_length_m=17.709)


def test_archive_expanding_past_the_limit_is_refused(tmp_path: Path) -> None:
    archive = raw_tar_gz(tmp_path / "bomb.tar.gz", [_member("sim-trace/big.csv", b"0" * 3_000_000)])
    with pytest.raises(PayloadTooLarge, match="expands to more than"):
        read_export(archive, limits=ExportLimits(max_expanded_bytes=1_000_000))


def test_oversized_metrics_file_is_refused(tmp_path: Path) -> None:
    archive = raw_tar_gz(tmp_path / "big.tar.gz", [_member("metrics/TrainingMetrics.json", b" " * 5000)])
    with pytest.raises(PayloadTooLarge, match="metrics/TrainingMetrics.json is larger than"):
        read_export(archive, limits=ExportLimits(max_file_bytes=4096))


def test_not_an_archive(tmp_path: Path) -> None:
    path = tmp_path / "model.tar.gz"
    path.write_bytes(b"PK\x03\x04 a zip file")
    with pytest.raises(InvalidInput, match="not a .tar.gz"):
        read_export(path)


# -- the track is read from every place the export names it (real console/DROA exports have no params YAML) --------

CONSOLE_EVALUATION = "evaluation-20201021101010-XyXyXyXyXyXyXyXyXyXyXy"


def test_console_evaluation_log_on_another_track_is_refused(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    log = folder / f"logs/evaluation/{CONSOLE_EVALUATION}-robomaker.log"
    log.parent.mkdir(parents=True)
    log.write_text(console_log("Spain_track", f"{CONSOLE_EVALUATION}.json"))
    assert _problem(folder) == (f"logs/evaluation/{CONSOLE_EVALUATION}-robomaker.log: WORLD_NAME: the evaluation ran "
                                "on 'Spain_track', not on 'reinvent_base'")
    # Pushed for the track the log names, the sim-trace's track_len (re:Invent 2018's 17.71 m) still says otherwise.
    assert "track_len: the evaluation ran on a track 17.71 m long; Spain_track is 60.00 m" in _problem(folder,
                                                                                                      "Spain_track")


def test_only_the_submitted_evaluations_log_decides_when_an_export_holds_several(tmp_path: Path) -> None:
    # A racer's console export keeps every evaluation; the laps submitted are the newest one's, on reinvent_base.
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    older = "evaluation-20201001101010-OldOldOldOldOldOldOldO"
    (folder / f"metrics/evaluation/{older}.json").write_text("{}")  # older: not the one read
    logs = folder / "logs/leaderboard"
    logs.mkdir(parents=True)
    (logs / f"leaderboard-20201001-{older}-robomaker.log").write_text(console_log("Spain_track", f"{older}.json"))
    (logs / f"leaderboard-20201021-{CONSOLE_EVALUATION}-robomaker.log").write_text(
        console_log("reinvent_base", f"{CONSOLE_EVALUATION}.json"))
    assert [t.time_s for t in build(folder).trials] == [16.468, 16.267, 9.0]


def test_an_unpaired_evaluation_log_for_another_track_is_refused(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    log = folder / "logs/evaluation/evaluation-elsewhere-robomaker.log"
    log.parent.mkdir(parents=True)
    log.write_text(console_log("Spain_track", "evaluation-elsewhere.json"))
    assert "evaluation-elsewhere-robomaker.log: WORLD_NAME: the evaluation ran on 'Spain_track'" in _problem(folder)


def test_droa_export_reads_the_lower_case_world_name_of_its_simulation_logs(tmp_path: Path) -> None:
    folder = droa_export(tmp_path / "indy", world="Spain_track", eval_world="Spain_track", laps=LAPS)
    submission = build(folder, track="Spain_track")
    assert submission.layout == "console-new" and submission.training_track == "Spain_track"
    assert submission.training_episodes == 3

    pushed_elsewhere = droa_export(tmp_path / "indy2", world="Spain_track", eval_world="Spain_track", laps=LAPS)
    message = _problem(pushed_elsewhere, track="reinvent_base")
    assert message.startswith("logs/evaluation/2026-03-07T17:59:20.610Z-deepracerindy-evaluation-9oJ3QbS0SYm7Iag-"
                              "simulation.log: WORLD_NAME: the evaluation ran on 'Spain_track'")


def test_old_console_training_log_names_the_track_without_a_params_file(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    for log in (folder / "logs/training").glob("*robomaker.log"):
        log.write_text(console_log("reInvent2019_track", "training-x.json").replace("EVALUATION", "TRAINING"))
    assert not list(folder.rglob("*params*.yaml"))
    assert build(folder).training_track == "reInvent2019_track"


def test_drfc_with_several_workers_counts_every_workers_episodes(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    (folder / "metrics/TrainingMetrics_1.json").write_text(json.dumps(training_metrics([10, 20, 30])))
    (folder / "metrics/TrainingMetrics_2.json").write_text(json.dumps(training_metrics([40, 100])))
    submission = build(folder)
    assert submission.training_episodes == 5 + 3 + 2  # the main worker's 5 plus workers 1 and 2
    assert submission.training_best_completion_pct == 100.0


# -- the real layouts as downloaded (deepracer-utils tests/deepracer/logs/sample-*) -----------------------------------

def test_real_drfc_prefix_has_no_params_yaml_and_its_simtrace_names_the_track(tmp_path: Path) -> None:
    """sample-drfc-1-logs holds no training_params.yaml: that used to stop the push; now the evaluation's sim-trace
    (track_len 17.709159380834848, re:Invent 2018) is the evidence, and it decides."""
    folder = drfc_export(tmp_path / "drfc-1", world="reinvent_base", laps=LAPS, params=False)
    submission = build(folder)
    assert submission.training_track is None and [t.time_s for t in submission.trials] == [16.468, 16.267, 9.0]
    message = _problem(folder, "Spain_track")
    assert message == ("evaluation-20240102030405/evaluation-simtrace/0-iteration.csv: track_len: the evaluation ran "
                       "on a track 17.71 m long; Spain_track is 60.00 m")


def test_three_worker_drfc_export_evaluated_elsewhere_is_refused(tmp_path: Path) -> None:
    folder = drfc_export(tmp_path / "drfc-3", world="reinvent_base", laps=LAPS, params=False)
    for worker in (1, 2):
        (folder / f"metrics/TrainingMetrics_{worker}.json").write_text(json.dumps(training_metrics([10, 100])))
    assert build(folder).training_episodes == 5 + 2 + 2
    assert "track_len: the evaluation ran on a track 17.71 m long; reInvent2019_track is 23.12 m" in _problem(
        folder, "reInvent2019_track")


def test_edited_evaluation_metrics_disagree_with_their_simtrace(tmp_path: Path) -> None:
    """The cheat: EvaluationMetrics edited to a 5.123 s lap; the evaluation's sim-trace still shows 16.468 s."""
    folder = drfc_export(tmp_path / "m", world="reinvent_base", laps=LAPS, params=False)
    path = folder / "metrics/EvaluationMetrics-20240102030405.json"
    document = json.loads(path.read_text())
    document["metrics"][0]["elapsed_time_in_milliseconds"] = 5123
    path.write_text(json.dumps(document))
    assert _problem(folder) == (
        "metrics/EvaluationMetrics-20240102030405.json: metrics[0].elapsed_time_in_milliseconds: claims 5.123 s, but "
        "its sim-trace (evaluation-20240102030405/evaluation-simtrace/0-iteration.csv) shows the trial lasted "
        "16.468 s")


def test_console_continuous_action_export(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "continuous", world="reinvent_base", laps=LAPS,
                                metadata=CONTINUOUS_SAC_METADATA)
    submission = build(folder)
    assert submission.action_space == "continuous, steering -30..30 deg, speed 1..2 m/s"
    assert submission.top_speed_m_s == 2.0


def test_droa_archive_with_colons_in_every_name_is_read(tmp_path: Path) -> None:
    """DROA names logs and metrics `2026-03-07T17:52:00.898Z-…`: the member check used to drop them all."""
    folder = droa_export(tmp_path / "indy", world="Spain_track", eval_world="Spain_track",
                         laps=[(31000, 100), (30500, 100)])
    archive = tar_gz_of(folder, tmp_path / "indy.tar.gz", top="indy")
    submission = build(archive, track="Spain_track")
    assert [t.time_s for t in submission.trials] == [31.0, 30.5] and submission.training_track == "Spain_track"


def test_missing_files_say_where_the_racers_tool_writes_them(tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "logs-only", world="reinvent_base", laps=LAPS)
    (folder / "model/model_metadata.json").unlink()
    message = _problem(folder)
    assert message.startswith("model/model_metadata.json: missing")
    assert "model download" in message and "drem league push LOGS MODEL.tar.gz" in message
    drfc = drfc_export(tmp_path / "no-eval", world="reinvent_base", laps=LAPS)
    for path in (drfc / "metrics").glob("EvaluationMetrics-*.json"):
        path.unlink()
    message = _problem(drfc)
    assert message.startswith("metrics/evaluation/*.json: missing") and "dr-start-evaluation" in message


def test_the_same_laps_give_the_same_digest_whatever_the_file_looks_like(tmp_path: Path) -> None:
    first = build(console_old_export(tmp_path / "a", world="reinvent_base", laps=LAPS))
    folder = console_old_export(tmp_path / "b", world="reinvent_base", laps=LAPS)
    path = next((folder / "metrics/evaluation").glob("*.json"))
    path.write_text(json.dumps(json.loads(path.read_text()), indent=4))  # re-indented copy
    assert build(folder).evidence_digest == first.evidence_digest
    other = build(console_old_export(tmp_path / "c", world="reinvent_base", laps=[(16469, 100)]))
    assert other.evidence_digest != first.evidence_digest


def test_an_older_evaluation_on_another_track_does_not_block_the_submitted_one(tmp_path: Path) -> None:
    """A console export keeps every evaluation's sim-trace: the submitted evaluation's own one decides."""
    folder = console_old_export(tmp_path / "m", world="reinvent_base", laps=LAPS)
    older = folder / "sim-trace/evaluation/20201001101010-OldOldOldOldOldOldOldO/evaluation-simtrace/0-iteration.csv"
    older.parent.mkdir(parents=True)
    older.write_text(simtrace("Spain_track", [(40000, 100)]))
    assert [t.time_s for t in build(folder).trials] == [16.468, 16.267, 9.0]
    (folder / "sim-trace/evaluation/20201021101010-XyXyXyXyXyXyXyXyXyXyXy").rename(folder / "sim-trace/unpaired")
    assert "track_len" in _problem(folder)  # without its own trace, every trace in the export must agree
