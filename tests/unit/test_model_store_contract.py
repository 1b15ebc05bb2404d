"""The in-memory model store of the fast domain tier (tests/in_memory/models.py) behaves as DynamoModelStore does (over
moto) on every point ModelService relies on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.core.errors import InvalidInput, UpstreamError
from chalicelib.domain.racer_models import ModelChanged, ModelRecord, ModelStatus, ScrutineerResult
from tests.in_memory.models import InMemoryModelStore

pytestmark = pytest.mark.unit


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryModelStore()
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.racer_models import DynamoModelStore

    request.getfixturevalue("stack")
    return DynamoModelStore(clients.dynamodb(), get_settings().table("models"))


def a_model(model_id: str = "0001aa", owner: str = "alice", status: ModelStatus = ModelStatus.AVAILABLE,
            uploaded_at: str = "2026-05-14T10:00:00Z", **fields: Any) -> ModelRecord:
    return ModelRecord(model_id=model_id, owner_sub=f"{owner}-sub", owner_username=owner, name=f"model {model_id}",
                       status=status, uploaded_at=uploaded_at, updated_at=uploaded_at,
                       upload_key=f"uploads/{owner}/{model_id}.tar.gz", **fields)


def every_page(list_page: Any, limit: int) -> list[str]:
    """The model ids of a listing read page by page to its end (no page holds more than `limit`)."""
    found, token = [], None
    while True:
        page = list_page(limit=limit, next_token=token)
        assert len(page.models) <= limit
        found += [m.model_id for m in page.models]
        token = page.next_token
        if not token:
            return found


def test_a_model_reads_back_by_owner_and_by_id_and_a_missing_one_is_none(store: Any) -> None:
    model = a_model(model_md5="m" * 32, sensor=["FRONT_FACING_CAMERA"], conversion_max_diff=0.25,
                    scrutineer_result=ScrutineerResult(verdict="passed", message="3 laps", track="reinvent_base"))
    store.create(model)
    assert store.get("alice-sub", "0001aa") == model
    assert store.get_by_id("0001aa") == model and store.owner_of("0001aa") == "alice-sub"
    assert store.get("bob-sub", "0001aa") is None
    assert store.get_by_id("nope") is None and store.owner_of("nope") is None


def test_the_converters_own_message_is_kept_for_staff(store: Any) -> None:
    store.create(a_model(scrutiny="cannot_scrutineer", scrutiny_reason="stereo", scrutiny_detail="OpenVINO said"))
    stored = store.get_by_id("0001aa")
    assert (stored.scrutiny_reason, stored.scrutiny_detail) == ("stereo", "OpenVINO said")


def test_creating_a_model_id_twice_is_refused_and_keeps_the_first(store: Any) -> None:
    store.create(a_model())
    with pytest.raises(UpstreamError, match="TransactionCanceledException"):
        store.create(a_model(owner="bob"))
    assert store.owner_of("0001aa") == "alice-sub"


def test_a_replace_needs_the_status_and_the_result_its_writer_read(store: Any) -> None:
    store.create(a_model(status=ModelStatus.UPLOADED))
    with pytest.raises(ModelChanged):
        store.replace(a_model(status=ModelStatus.QUARANTINED), expected_status=ModelStatus.AVAILABLE)
    store.replace(a_model(), expected_status=ModelStatus.UPLOADED)
    assert store.get_by_id("0001aa").status is ModelStatus.AVAILABLE
    with pytest.raises(ModelChanged):  # nothing stored under this id: nothing to replace, nothing created
        store.replace(a_model("0002aa"), expected_status=ModelStatus.AVAILABLE)
    assert store.get_by_id("0002aa") is None

    read = store.get_by_id("0001aa")
    driven = a_model(scrutineer_result=ScrutineerResult(verdict="passed", message="ok", track="reinvent_base"))
    store.replace(driven, expected_status=ModelStatus.AVAILABLE, result_as_in=read)  # no result yet: as read
    with pytest.raises(ModelChanged):  # a second worker that read the model before the first one's result
        store.replace(a_model(scrutineer_result=ScrutineerResult(verdict="failed", message="off", track="x")),
                      expected_status=ModelStatus.AVAILABLE, result_as_in=read)
    store.replace(driven.model_copy(update={"name": "renamed"}), expected_status=ModelStatus.AVAILABLE,
                  result_as_in=driven)  # the result it read is the stored one: the write goes through
    assert store.get_by_id("0001aa").name == "renamed"


def test_an_owners_models_list_newest_first_page_by_page_without_deleted_unless_asked(store: Any) -> None:
    for model_id in ("0001aa", "0002aa", "0003aa", "0004aa", "0005aa"):
        store.create(a_model(model_id))
    store.create(a_model("0006aa", status=ModelStatus.DELETED))
    store.create(a_model("0007aa", owner="bob"))

    def alices(**kwargs: Any) -> Any:
        return store.list_owner("alice-sub", **kwargs)

    assert every_page(alices, limit=2) == ["0005aa", "0004aa", "0003aa", "0002aa", "0001aa"]
    assert every_page(lambda **kw: store.list_owner("alice-sub", include_deleted=True, **kw), limit=100) == [
        "0006aa", "0005aa", "0004aa", "0003aa", "0002aa", "0001aa"]
    assert every_page(lambda **kw: store.list_owner("carol-sub", **kw), limit=10) == []


def test_every_model_lists_by_upload_time_without_deleted_ones(store: Any) -> None:
    store.create(a_model("0001aa", uploaded_at="2026-05-14T12:00:00Z"))
    store.create(a_model("0002aa", owner="bob", uploaded_at="2026-05-14T11:00:00Z"))
    store.create(a_model("0003aa", uploaded_at="2026-05-14T13:00:00Z", status=ModelStatus.DELETED))
    store.create(a_model("0004aa", owner="bob", uploaded_at="2026-05-14T10:00:00Z", status=ModelStatus.UPLOADED))
    assert every_page(store.list_all, limit=1) == ["0001aa", "0002aa", "0004aa"]
    store.replace(a_model("0001aa", status=ModelStatus.DELETED, uploaded_at="2026-05-14T12:00:00Z"),
                  expected_status=ModelStatus.AVAILABLE)  # a soft delete takes it out of the listing
    assert every_page(store.list_all, limit=10) == ["0002aa", "0004aa"]


def test_a_page_token_is_good_only_for_the_listing_that_gave_it(store: Any) -> None:
    for model_id in ("0001aa", "0002aa", "0003aa"):
        store.create(a_model(model_id))
    token = store.list_owner("alice-sub", limit=1, next_token=None).next_token
    assert token
    with pytest.raises(InvalidInput, match="not valid here") as refused:
        store.list_owner("bob-sub", limit=1, next_token=token)
    assert refused.value.field == "next"
    with pytest.raises(InvalidInput):
        store.list_owner("alice-sub", limit=1, next_token="not-a-token")


def test_available_models_are_found_by_their_md5_per_owner(store: Any) -> None:
    store.create(a_model("0002aa", model_md5="same"))
    store.create(a_model("0001aa", model_md5="same"))
    store.create(a_model("0003aa", model_md5="same", status=ModelStatus.QUARANTINED))
    store.create(a_model("0004aa", owner="bob", model_md5="same"))
    store.create(a_model("0005aa", model_md5="other"))
    assert [m.model_id for m in store.find_available_by_md5("alice-sub", "same")] == ["0001aa", "0002aa"]
    assert store.find_available_by_md5("carol-sub", "same") == []
