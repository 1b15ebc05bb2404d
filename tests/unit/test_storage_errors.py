"""What a storage outage answers: 'cannot be reached' only when nothing was written; once a request has sent a write,
the answer says the change may or may not have been stored (and how to find out)."""
from __future__ import annotations

import pytest
from botocore.exceptions import ConnectionClosedError, EndpointConnectionError

from chalicelib import logs
from chalicelib.core.errors import MaybeStored, ServiceUnavailable
from chalicelib.storage.aws_errors import is_write, note_write_sent, translate_common

pytestmark = pytest.mark.unit


class _Operation:
    def __init__(self, name: str) -> None:
        self.name = name


@pytest.fixture
def in_a_request():
    logs._local.request = {"request_id": "req-1", "principal": "anonymous"}
    yield
    logs._local.request = None


def test_reads_and_writes_are_told_apart_by_operation_name():
    assert not any(is_write(op) for op in ("get_item", "query", "scan", "admin_get_user", "list_users",
                                           "admin_list_groups_for_user", "initiate_auth", "head_object"))
    assert all(is_write(op) for op in ("put_item", "transact_write_items", "admin_create_user", "sign_up",
                                       "admin_add_user_to_group", "delete_object"))


def test_a_failed_read_says_cannot_be_reached(in_a_request):
    error = translate_common(EndpointConnectionError(endpoint_url="http://127.0.0.1:1"), "The events table")
    assert type(error) is ServiceUnavailable and error.message == "The events table cannot be reached."


def test_a_failed_write_says_it_may_have_been_stored(in_a_request):
    error = translate_common(ConnectionClosedError(endpoint_url="http://127.0.0.1:1"), "The events table", write=True)
    assert isinstance(error, MaybeStored)
    assert "may or may not have been stored" in error.message and "same key" in error.message


def test_a_failed_read_after_a_write_of_the_same_request_does_not_claim_nothing_happened(in_a_request):
    note_write_sent(model=_Operation("AdminCreateUser"))
    error = translate_common(EndpointConnectionError(endpoint_url="http://127.0.0.1:1"), "The account service")
    assert isinstance(error, MaybeStored)
    logs._local.request = {"request_id": "req-2", "principal": "anonymous"}  # the next request starts clean
    assert type(translate_common(EndpointConnectionError(endpoint_url="x"), "The account service")) \
        is ServiceUnavailable


def test_the_storage_servers_full_disk_refusal_reaches_the_user_as_507_in_its_own_words(in_a_request):
    from botocore.exceptions import ClientError

    from chalicelib.core.errors import StorageDiskFull
    from chalicelib.http_errors import status_for

    words = "drem's data disk is full at /srv/drem: free space on that disk, then try again"
    refused = ClientError({"Error": {"Code": "DremDataDiskFull", "Message": words},
                           "ResponseMetadata": {"HTTPStatusCode": 507}}, "PutItem")
    error = translate_common(refused, "The events table", write=True)
    assert isinstance(error, StorageDiskFull) and error.message == words
    assert status_for(error) == 507
