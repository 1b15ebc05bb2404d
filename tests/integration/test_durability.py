"""Every write the durable server acknowledged survives `kill -9` at a random moment.

A writer thread does a random mix of DynamoDB, S3 (plain and multipart) and Cognito writes and records each one
only once the server has answered it; a killer thread sends SIGKILL at a random point in that stream. After a
restart on the same state dir, every acknowledged write must be there with the same value, the same bytes, the
same pool/client ids, and users must still log in with the same `sub`.
"""
from __future__ import annotations

import base64
import hashlib
import json
import random
import threading
from dataclasses import dataclass, field

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.durability]

TABLE = "durability-items"
BUCKET = "durability-objects"
POOL = "durability-users"
PASSWORD = "Durable-Passw0rd!"
PART_BYTES = 5 * 1024 * 1024  # S3's minimum size for every part but the last


@dataclass
class Acknowledged:
    items: dict[str, str] = field(default_factory=dict)
    counter: int = 0
    objects: dict[str, str] = field(default_factory=dict)  # key -> md5
    users: dict[str, str] = field(default_factory=dict)  # username -> sub
    count: int = 0


def _set_up(clients) -> tuple[str, str]:
    clients.dynamodb.create_table(
        TableName=TABLE, BillingMode="PAY_PER_REQUEST",
        KeySchema=[{"AttributeName": "pk", "KeyType": "HASH"}, {"AttributeName": "sk", "KeyType": "RANGE"}],
        AttributeDefinitions=[{"AttributeName": "pk", "AttributeType": "S"},
                              {"AttributeName": "sk", "AttributeType": "S"}])
    clients.s3.create_bucket(Bucket=BUCKET)
    pool_id = clients.cognito.create_user_pool(PoolName=POOL)["UserPool"]["Id"]
    client_id = clients.cognito.create_user_pool_client(
        UserPoolId=pool_id, ClientName="web",
        ExplicitAuthFlows=["ALLOW_USER_PASSWORD_AUTH", "ALLOW_REFRESH_TOKEN_AUTH"])["UserPoolClient"]["ClientId"]
    return pool_id, client_id


def _write_one(op: str, step: int, rng: random.Random, clients, pool_id: str, acked: Acknowledged) -> None:
    if op == "put_item":
        pk, value = f"item-{step}", f"value-{rng.getrandbits(64):x}"
        clients.dynamodb.put_item(TableName=TABLE, Item={"pk": {"S": pk}, "sk": {"S": "v"}, "value": {"S": value}})
        acked.items[pk] = value
    elif op == "update_item":
        answer = clients.dynamodb.update_item(
            TableName=TABLE, Key={"pk": {"S": "counter"}, "sk": {"S": "v"}},
            UpdateExpression="ADD hits :one", ExpressionAttributeValues={":one": {"N": "1"}}, ReturnValues="ALL_NEW")
        acked.counter = int(answer["Attributes"]["hits"]["N"])
    elif op == "put_object":
        key, body = f"objects/{step}.bin", rng.randbytes(rng.randint(1, 64 * 1024))
        clients.s3.put_object(Bucket=BUCKET, Key=key, Body=body)
        acked.objects[key] = hashlib.md5(body).hexdigest()
    elif op == "multipart":
        key = f"multipart/{step}.bin"
        parts = [rng.randbytes(PART_BYTES), rng.randbytes(rng.randint(1, 4096))]
        upload_id = clients.s3.create_multipart_upload(Bucket=BUCKET, Key=key)["UploadId"]
        etags = [clients.s3.upload_part(Bucket=BUCKET, Key=key, UploadId=upload_id, PartNumber=n, Body=part)["ETag"]
                 for n, part in enumerate(parts, start=1)]
        clients.s3.complete_multipart_upload(
            Bucket=BUCKET, Key=key, UploadId=upload_id,
            MultipartUpload={"Parts": [{"ETag": etag, "PartNumber": n} for n, etag in enumerate(etags, start=1)]})
        acked.objects[key] = hashlib.md5(b"".join(parts)).hexdigest()
    elif op == "user":
        username = f"racer{step}"
        created = clients.cognito.admin_create_user(UserPoolId=pool_id, Username=username,
                                                    TemporaryPassword="Temp-Passw0rd!", MessageAction="SUPPRESS")
        clients.cognito.admin_set_user_password(UserPoolId=pool_id, Username=username, Password=PASSWORD,
                                                Permanent=True)
        acked.users[username] = _attribute(created["User"]["Attributes"], "sub")
    acked.count += 1


def _attribute(attributes: list[dict[str, str]], name: str) -> str:
    return next(a["Value"] for a in attributes if a["Name"] == name)


def _claims(token: str) -> dict:
    payload = token.split(".")[1]
    return json.loads(base64.urlsafe_b64decode(payload + "=" * (-len(payload) % 4)))


def _operations(rng: random.Random, count: int) -> list[str]:
    ops = rng.choices(["put_item", "update_item", "put_object", "user"], weights=[4, 3, 3, 1], k=count)
    ops.insert(rng.randint(0, 25), "multipart")
    return ops


@pytest.mark.parametrize("seed", range(10))
def test_every_acknowledged_write_survives_kill_9(durable_server_factory, seed: int):
    rng = random.Random(seed)
    # Short intervals make the kill land on every phase: journal only, mid-snapshot, snapshot + journal tail.
    server = durable_server_factory.start(f"kill-{seed}", snapshot_interval=rng.choice([0.05, 0.2, 1.0, 5.0]))
    clients = server.clients()
    pool_id, client_id = _set_up(clients)

    acked = Acknowledged()
    kill_after = rng.randint(1, 60)
    enough_written = threading.Event()
    writer_stopped = threading.Event()

    def writer() -> None:
        try:
            for step, op in enumerate(_operations(rng, 200)):
                _write_one(op, step, rng, clients, pool_id, acked)
                if acked.count >= kill_after:
                    enough_written.set()
        except Exception:
            pass  # the server was killed under this request: it was never acknowledged
        finally:
            enough_written.set()
            writer_stopped.set()

    def killer() -> None:
        enough_written.wait(30)
        writer_stopped.wait(rng.uniform(0, 0.05))  # a random moment, often mid-request
        server.kill9()

    threads = [threading.Thread(target=writer), threading.Thread(target=killer)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert acked.count >= 1, "the writer never got a write acknowledged"

    server.start()
    after = server.clients(retries=3)

    for pk, value in acked.items.items():
        item = after.dynamodb.get_item(TableName=TABLE, Key={"pk": {"S": pk}, "sk": {"S": "v"}}).get("Item")
        assert item is not None and item["value"]["S"] == value, f"lost or changed item {pk}"
    if acked.counter:
        stored = after.dynamodb.get_item(TableName=TABLE, Key={"pk": {"S": "counter"}, "sk": {"S": "v"}})["Item"]
        # The update in flight at the kill was journaled before it ran, so it may have landed (+1), never less.
        assert acked.counter <= int(stored["hits"]["N"]) <= acked.counter + 1
    for key, md5 in acked.objects.items():
        body = after.s3.get_object(Bucket=BUCKET, Key=key)["Body"].read()
        assert hashlib.md5(body).hexdigest() == md5, f"object {key} lost or changed"

    pools = after.cognito.list_user_pools(MaxResults=10)["UserPools"]
    assert [p["Id"] for p in pools] == [pool_id]
    clients_after = after.cognito.list_user_pool_clients(UserPoolId=pool_id)["UserPoolClients"]
    assert [c["ClientId"] for c in clients_after] == [client_id]
    for username, sub in acked.users.items():
        user = after.cognito.admin_get_user(UserPoolId=pool_id, Username=username)
        assert _attribute(user["UserAttributes"], "sub") == sub
        tokens = after.cognito.initiate_auth(ClientId=client_id, AuthFlow="USER_PASSWORD_AUTH",
                                             AuthParameters={"USERNAME": username, "PASSWORD": PASSWORD})
        assert _claims(tokens["AuthenticationResult"]["IdToken"])["sub"] == sub

    health = server.health()
    assert health["recovery_failed_records"] == 0
    server.stop()


def test_clean_stop_snapshots_and_empties_the_journal(durable_server_factory):
    server = durable_server_factory.start("clean-stop")
    clients = server.clients()
    _set_up(clients)
    clients.dynamodb.put_item(TableName=TABLE, Item={"pk": {"S": "kept"}, "sk": {"S": "v"}})
    assert server.health()["journal_records"] > 0

    assert server.stop() == 0
    server.start()

    health = server.health()
    assert health["journal_records"] == 0 and health["recovered_records"] == 0
    assert health["snapshot_bytes"] > 0
    item = server.clients().dynamodb.get_item(TableName=TABLE, Key={"pk": {"S": "kept"}, "sk": {"S": "v"}})
    assert "Item" in item
    server.stop()



def test_a_signed_in_racer_keeps_their_session_after_kill_9_with_no_snapshot_since(durable_server_factory):
    """Sign-ins are journaled, not snapshotted (classify.py): after a crash the replayed sign-in holds the same refresh
    token, so the racer's browser stays signed in."""
    server = durable_server_factory.start("sign-in-kill", snapshot_interval=3600)
    clients = server.clients()
    pool_id, client_id = _set_up(clients)
    clients.cognito.admin_create_user(UserPoolId=pool_id, Username="racer", TemporaryPassword="Temp-Passw0rd!",
                                      MessageAction="SUPPRESS")
    clients.cognito.admin_set_user_password(UserPoolId=pool_id, Username="racer", Password=PASSWORD, Permanent=True)
    snapshots_before = server.health()["snapshot_bytes"]
    signed_in = clients.cognito.initiate_auth(ClientId=client_id, AuthFlow="USER_PASSWORD_AUTH",
                                              AuthParameters={"USERNAME": "racer", "PASSWORD": PASSWORD})
    refresh_token = signed_in["AuthenticationResult"]["RefreshToken"]
    assert server.health()["snapshot_bytes"] == snapshots_before, "the sign-in was snapshotted"

    server.kill9()
    server.start()

    refreshed = server.clients(retries=3).cognito.initiate_auth(
        ClientId=client_id, AuthFlow="REFRESH_TOKEN_AUTH", AuthParameters={"REFRESH_TOKEN": refresh_token})
    sub = _claims(signed_in["AuthenticationResult"]["IdToken"])["sub"]
    assert _claims(refreshed["AuthenticationResult"]["IdToken"])["sub"] == sub
    server.stop()
