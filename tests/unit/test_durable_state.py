"""Recovery of the durable moto server: version pin, and snapshots + journal replayed exactly once, in order.

These drive moto's real WSGI app in-process through the durable middleware (no socket, no botocore), then
throw the in-memory backends away and recover from the state dir, as a restarted server would.
"""
from __future__ import annotations

import json
import threading

import pytest
from moto.core.base_backend import BackendDict
from werkzeug.test import Client

from drem_local.durable.__main__ import EXIT_VERSION_MISMATCH
from drem_local.durable.__main__ import main as durable_main
from drem_local.durable.server import DurableApp
from drem_local.durable.state import DurableState, MotoVersionMismatch, running_moto_version

pytestmark = pytest.mark.unit

_DDB_AUTH = ("AWS4-HMAC-SHA256 Credential=testing/20260101/us-east-1/dynamodb/aws4_request, "
             "SignedHeaders=host, Signature=0")
TABLE = "counters"


@pytest.fixture
def fresh_moto(monkeypatch):
    monkeypatch.setenv("MOTO_COGNITO_IDP_USER_POOL_ID_STRATEGY", "HASH")
    monkeypatch.setenv("MOTO_COGNITO_IDP_USER_POOL_CLIENT_ID_STRATEGY", "HASH")
    BackendDict.reset()
    yield
    BackendDict.reset()


def _server(state_dir) -> tuple[DurableApp, Client]:
    from moto.moto_server.werkzeug_app import DomainDispatcherApplication, create_backend_app

    app = DurableApp(DomainDispatcherApplication(create_backend_app), DurableState(state_dir, fsync=False))
    app.recover()
    return app, Client(app)


def _dynamodb(client: Client, operation: str, payload: dict) -> dict:
    response = client.post("/", data=json.dumps(payload), headers={
        "X-Amz-Target": f"DynamoDB_20120810.{operation}", "Content-Type": "application/x-amz-json-1.0",
        "Authorization": _DDB_AUTH})
    assert response.status_code == 200, response.get_data(as_text=True)
    return json.loads(response.get_data())


def _cognito(client: Client, operation: str, payload: dict) -> dict:
    response = client.post("/", data=json.dumps(payload), headers={
        "X-Amz-Target": f"AWSCognitoIdentityProviderService.{operation}",
        "Content-Type": "application/x-amz-json-1.1"})
    assert response.status_code == 200, response.get_data(as_text=True)
    return json.loads(response.get_data())


def _create_table(client: Client) -> None:
    _dynamodb(client, "CreateTable", {
        "TableName": TABLE, "BillingMode": "PAY_PER_REQUEST",
        "KeySchema": [{"AttributeName": "pk", "KeyType": "HASH"}],
        "AttributeDefinitions": [{"AttributeName": "pk", "AttributeType": "S"}]})


def _add_hit(client: Client) -> int:
    answer = _dynamodb(client, "UpdateItem", {
        "TableName": TABLE, "Key": {"pk": {"S": "c"}}, "UpdateExpression": "ADD hits :one",
        "ExpressionAttributeValues": {":one": {"N": "1"}}, "ReturnValues": "ALL_NEW"})
    return int(answer["Attributes"]["hits"]["N"])


def _hits(client: Client) -> int:
    return int(_dynamodb(client, "GetItem", {"TableName": TABLE, "Key": {"pk": {"S": "c"}}})["Item"]["hits"]["N"])


def test_snapshot_then_journal_tail_is_replayed_once_in_order(tmp_path, fresh_moto):
    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)
    assert app.snapshot_if_dirty()  # hits=1 now in the snapshot, journal emptied
    _add_hit(client)
    _add_hit(client)  # hits=3: two increments only in the journal
    app.state.close()
    BackendDict.reset()  # the process dies; memory is gone

    app, client = _server(tmp_path)

    assert _hits(client) == 3
    report = app.state.recovery
    assert (report.replayed, report.skipped, report.failed) == (2, 0, 0)


def test_requests_are_answered_while_a_snapshot_writes_its_files_and_what_they_change_survives(tmp_path, fresh_moto):
    """Writing a snapshot (seconds once S3 holds model archives) does not hold up requests: the public board reads
    storage meanwhile. A write answered during that time is in the journal and then in the next round's snapshot."""
    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)
    writing, go_on = threading.Event(), threading.Event()
    real_write_files = app.state.snapshots.write_files

    def slow_first_write(capture):
        if not writing.is_set():
            writing.set()
            assert go_on.wait(60), "the test never let the snapshot finish"
        return real_write_files(capture)

    app.state.snapshots.write_files = slow_first_write
    snapshot = threading.Thread(target=app.snapshot_if_dirty)
    snapshot.start()
    try:
        assert writing.wait(60), "the snapshot never started writing"
        assert _add_hit(client) == 2  # answered while the snapshot's files are being written
        assert _hits(client) == 2
    finally:
        go_on.set()
        snapshot.join(60)
    assert not snapshot.is_alive()
    assert app.state.journal.records == 0  # the next round took the hit in: the journal is empty again
    app.state.close()
    BackendDict.reset()

    app, client = _server(tmp_path)

    assert _hits(client) == 2
    assert app.state.recovery.journal_records == 0


def test_a_user_created_while_a_snapshot_writes_survives_even_though_the_snapshot_held_an_older_user_pool(
        tmp_path, fresh_moto, monkeypatch):
    """The snapshot being written holds the user pool as it was; a user created meanwhile is snapshotted at once (its
    sub is random). The older file must neither replace the newer one, nor be removed as unreferenced by that
    immediate snapshot before it is committed, or the state would not load (or the user be gone) after a restart."""
    from drem_local.durable import snapshot as snapshot_module

    app, client = _server(tmp_path)
    pool_id = _cognito(client, "CreateUserPool", {"PoolName": "racers"})["UserPool"]["Id"]
    _cognito(client, "CreateGroup", {"UserPoolId": pool_id, "GroupName": "racer"})  # cognito dirty: in the capture
    _create_table(client)
    _add_hit(client)  # and DynamoDB: its file is the one written last
    writing, go_on = threading.Event(), threading.Event()
    real_write = snapshot_module.write_atomically

    def slow_after_the_first_file(path, data):
        real_write(path, data)
        if threading.current_thread() is snapshot and path.name.startswith("dynamodb") and not writing.is_set():
            # both files are there, not committed yet
            writing.set()
            assert go_on.wait(60), "the test never let the snapshot finish"

    monkeypatch.setattr(snapshot_module, "write_atomically", slow_after_the_first_file)
    snapshot = threading.Thread(target=app.snapshot_if_dirty)
    snapshot.start()
    try:
        assert writing.wait(60), "the snapshot never started writing"
        _cognito(client, "AdminCreateUser", {"UserPoolId": pool_id, "Username": "ada", "MessageAction": "SUPPRESS"})
    finally:
        go_on.set()
        snapshot.join(60)
    assert not snapshot.is_alive()
    app.snapshot_if_dirty()
    assert app.state.journal.records == 0
    app.state.close()
    BackendDict.reset()

    _, client = _server(tmp_path)

    assert _cognito(client, "AdminGetUser", {"UserPoolId": pool_id, "Username": "ada"})["Username"] == "ada"
    groups = _cognito(client, "ListGroups", {"UserPoolId": pool_id})["Groups"]
    assert [g["GroupName"] for g in groups] == ["racer"]
    assert _hits(client) == 1


def test_a_service_snapshotted_early_does_not_get_its_journal_records_twice(tmp_path, fresh_moto):
    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)
    pool_id = _cognito(client, "CreateUserPool", {"PoolName": "racers"})["UserPool"]["Id"]  # snapshots cognito only
    _cognito(client, "CreateGroup", {"UserPoolId": pool_id, "GroupName": "admin"})
    _add_hit(client)
    app.state.close()
    BackendDict.reset()

    app, client = _server(tmp_path)

    assert _hits(client) == 2  # both increments replayed (DynamoDB had no snapshot)
    groups = _cognito(client, "ListGroups", {"UserPoolId": pool_id})["Groups"]
    assert [g["GroupName"] for g in groups] == ["admin"]  # pool from the snapshot, group from the journal
    assert app.state.recovery.skipped == 1  # CreateUserPool is in the cognito snapshot: not replayed again


def test_state_written_by_another_moto_version_is_refused_with_both_versions_named(tmp_path):
    (tmp_path / "moto-version").write_text("4.2.0\n")
    (tmp_path / "journal.bin").write_bytes(b"")

    with pytest.raises(MotoVersionMismatch) as refused:
        DurableState(tmp_path)

    message = str(refused.value)
    assert "4.2.0" in message and running_moto_version() in message
    assert "drem export" in message and f"rm -rf {tmp_path}" in message
    assert (tmp_path / "moto-version").read_text() == "4.2.0\n"  # nothing was overwritten


def test_the_server_command_exits_with_a_clear_message_on_a_version_mismatch(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MOTO_COGNITO_IDP_USER_POOL_ID_STRATEGY", "")
    monkeypatch.setenv("MOTO_COGNITO_IDP_USER_POOL_CLIENT_ID_STRATEGY", "")
    (tmp_path / "moto-version").write_text("4.2.0\n")

    code = durable_main(["--state-dir", str(tmp_path), "--port", "1"])

    assert code == EXIT_VERSION_MISMATCH
    assert "refusing to start" in capsys.readouterr().err


def test_a_fresh_state_dir_is_pinned_to_the_running_moto(tmp_path):
    DurableState(tmp_path / "new").close()

    assert (tmp_path / "new" / "moto-version").read_text().strip() == running_moto_version()


def test_a_read_only_disk_refuses_the_write_in_words_and_stores_nothing(tmp_path, fresh_moto):
    """Linux refuses to remount a filesystem read-only while the journal is open for writing, so here the journal's
    write fails as a disk that turned read-only under a running server does (EROFS; fault injection)."""
    import errno

    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)

    def read_only(*_args, **_kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    original = app.state.journal.append
    app.state.journal.append = read_only
    response = client.post("/", data=json.dumps({
        "TableName": TABLE, "Key": {"pk": {"S": "c"}}, "UpdateExpression": "ADD hits :one",
        "ExpressionAttributeValues": {":one": {"N": "1"}}}), headers={
        "X-Amz-Target": "DynamoDB_20120810.UpdateItem", "Content-Type": "application/x-amz-json-1.0",
        "Authorization": _DDB_AUTH})
    assert response.status_code == 507
    error = json.loads(response.get_data())
    assert error["__type"] == "DremDataDiskReadOnly"
    assert error["message"].startswith(f"drem's data disk is read-only at {tmp_path.resolve()}: make it writable")
    assert _hits(client) == 1  # moto never ran the refused write
    app.state.journal.append = original
    assert _add_hit(client) == 2  # and the sequence goes on where it was once the disk is back


def test_a_users_sub_is_drawn_again_the_same_from_the_journal_alone(tmp_path, fresh_moto):
    """No snapshot holds the user (a full disk refused them all): the replay of its journal record draws the same
    sub the client was told, because moto's randomness is seeded from the record."""
    app = DurableApp(_moto_app(), DurableState(tmp_path, fsync=False, seed_secret=b"k" * 32))
    app.recover()
    client = Client(app)
    pool_id = _cognito(client, "CreateUserPool", {"PoolName": "racers"})["UserPool"]["Id"]
    app.state.snapshots.write = _refuse_snapshot  # every snapshot from here on fails (ENOSPC)
    created = _cognito(client, "AdminCreateUser", {"UserPoolId": pool_id, "Username": "ada",
                                                   "MessageAction": "SUPPRESS"})
    told = next(a["Value"] for a in created["User"]["Attributes"] if a["Name"] == "sub")
    app.state.close()
    BackendDict.reset()

    again = DurableApp(_moto_app(), DurableState(tmp_path, fsync=False, seed_secret=b"k" * 32))
    again.recover()
    user = _cognito(Client(again), "AdminGetUser", {"UserPoolId": pool_id, "Username": "ada"})
    assert next(a["Value"] for a in user["UserAttributes"] if a["Name"] == "sub") == told


def _moto_app():
    from moto.moto_server.werkzeug_app import DomainDispatcherApplication, create_backend_app

    return DomainDispatcherApplication(create_backend_app)


def _refuse_snapshot(*_args, **_kwargs):
    import errno

    raise OSError(errno.ENOSPC, "No space left on device")


_S3_AUTH = ("AWS4-HMAC-SHA256 Credential=testing/20260101/us-east-1/s3/aws4_request, SignedHeaders=host, "
            "Signature=0")


def test_the_board_reads_and_writes_dynamodb_while_a_big_s3_object_is_still_being_stored_and_both_survive(
        tmp_path, fresh_moto):
    """A model archive being stored in S3 (moto takes a good part of a second for tens of MB) does not hold up the
    DynamoDB requests the public board and the races make; after a restart both writes are there, each once."""
    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)
    s3 = {"Authorization": _S3_AUTH, "Host": "localhost"}
    assert client.put("/models", headers=s3).status_code == 200
    storing, go_on = threading.Event(), threading.Event()
    real_moto = app.moto_app

    def slow_s3_put(environ, start_response):
        if environ["REQUEST_METHOD"] == "PUT" and environ["PATH_INFO"] == "/models/uploads/big.tar.gz":
            storing.set()
            assert go_on.wait(60), "the test never let the S3 write finish"
        return real_moto(environ, start_response)

    app.moto_app = slow_s3_put
    archive = b"\x1f\x8b" + bytes(range(256)) * 4096  # 1 MiB
    answers: list[int] = []
    upload = threading.Thread(target=lambda: answers.append(
        client.put("/models/uploads/big.tar.gz", data=archive, headers=s3).status_code))
    upload.start()
    try:
        assert storing.wait(60), "the S3 write never reached moto"
        assert _hits(client) == 1  # a board read, answered while the archive is in moto
        assert _add_hit(client) == 2  # and a race's write
    finally:
        go_on.set()
        upload.join(60)
    assert answers == [200]
    app.state.close()
    BackendDict.reset()

    _app, client = _server(tmp_path)

    assert _hits(client) == 2
    stored = client.get("/models/uploads/big.tar.gz", headers=s3)
    assert stored.status_code == 200 and stored.get_data() == archive


def test_the_board_is_answered_while_s3_is_pickled_for_a_snapshot_and_the_journal_still_empties(tmp_path, fresh_moto):
    """Pickling S3 (tens of ms per model archive it holds) holds S3's lane only: DynamoDB reads and writes are answered
    meanwhile, the snapshot round still ends with an empty journal, and after a restart everything is there once."""
    app, client = _server(tmp_path)
    _create_table(client)
    _add_hit(client)
    s3 = {"Authorization": _S3_AUTH, "Host": "localhost"}
    assert client.put("/models", headers=s3).status_code == 200
    assert client.put("/models/models/a.tar.gz", data=b"archive", headers=s3).status_code == 200
    pickling, go_on = threading.Event(), threading.Event()
    real_capture = app.state.snapshots.capture

    def slow_s3_capture(services, seq):
        if "s3" in services and not pickling.is_set():
            pickling.set()
            assert go_on.wait(60), "the test never let the snapshot go on"
        return real_capture(services, seq)

    app.state.snapshots.capture = slow_s3_capture
    snapshot = threading.Thread(target=app.snapshot_if_dirty)
    snapshot.start()
    try:
        assert pickling.wait(60), "the snapshot never pickled S3"
        assert _hits(client) == 1  # the board's read, answered while S3 is being pickled
        assert _add_hit(client) == 2
    finally:
        go_on.set()
        snapshot.join(60)
    assert not snapshot.is_alive()
    assert app.state.journal.records == 0
    app.state.close()
    BackendDict.reset()

    again, client = _server(tmp_path)

    assert _hits(client) == 2
    assert client.get("/models/models/a.tar.gz", headers=s3).get_data() == b"archive"
    assert again.state.recovery.journal_records == 0


def test_writes_arriving_during_every_snapshot_round_are_kept_by_the_journal_without_stopping_requests(
        tmp_path, fresh_moto):
    """Busy storage (a write lands while each round's files are written) does not make a snapshot hold every request
    while it writes: the journal keeps the newer writes until a later snapshot, a restart replays them, and a forced
    snapshot (the one at a clean stop) empties it."""
    app, client = _server(tmp_path)
    _create_table(client)
    real_write_files = app.state.snapshots.write_files
    answered_while_writing: list[int] = []

    def busy_write(capture):
        answered_while_writing.append(_add_hit(client))  # would wait forever if the round held the lanes
        return real_write_files(capture)

    app.state.snapshots.write_files = busy_write
    app.snapshot_if_dirty()

    assert answered_while_writing == [1, 2, 3]
    assert app.state.journal.records > 0
    app.state.snapshots.write_files = real_write_files
    app.state.close()
    BackendDict.reset()

    again, client = _server(tmp_path)
    assert _hits(client) == 3
    again.snapshot_if_dirty(force=True)
    assert again.state.journal.records == 0


def test_an_s3_answer_in_its_own_lane_leaves_a_sign_up_s_seeded_ids_alone(tmp_path, fresh_moto):
    """A Cognito sign-up draws its racer's `sub` from moto's source, seeded from its journal record so a replay after
    a crash draws the same one. S3 requests run in their own lane, at the same time: every moto answer draws a request
    id, and one drawn from that source between the seed and the `sub` would give the racer another `sub` on replay."""
    from moto.moto_api._internal import mock_random

    app, client = _server(tmp_path)
    s3 = {"Authorization": _S3_AUTH, "Host": "localhost"}
    assert client.put("/models", headers=s3).status_code == 200
    app.state.seed_randomness(7)
    sub_as_told = mock_random.uuid4()

    app.state.seed_randomness(7)
    answer = client.get("/models/models/missing.tar.gz", headers=s3)  # an S3 answer between the seed and the draw
    assert answer.status_code == 404 and answer.headers.get("x-amzn-requestid")
    assert mock_random.uuid4() == sub_as_told
