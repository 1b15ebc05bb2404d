"""Which kind of model archive this is, from the members it holds, and what drem keeps about it.

Three layouts are accepted: the DeepRacer console's (`agent/model.pb`, metadata at the top), deepracer-on-aws's flat
one (`model.pb`, metadata at the top or under `agent/`) and drem's own (`model.onnx`, optionally with an
`agent/model.pb` copy for stock cars that its metadata names).
"""
from __future__ import annotations

from collections.abc import Mapping

from chalicelib.formats.model_archive.report import ModelKind, not_valid
from chalicelib.formats.model_metadata import (
    ModelMetadata,
    ModelMetadataError,
    check_for_stock_car,
    parse_model_metadata_json,
)

METADATA_MEMBER = "model_metadata.json"
# DROA (deepracer-on-aws) also accepts metadata under agent/; we do too, but only when the root copy is absent.
METADATA_FALLBACK_MEMBER = "agent/model_metadata.json"
METADATA_MEMBERS = (METADATA_MEMBER, METADATA_FALLBACK_MEMBER)
TENSORFLOW_MEMBERS = ("agent/model.pb", "model.pb")  # console layout first, DROA's flat layout second
ONNX_MEMBER = "model.onnx"


def metadata_member(present: Mapping[str, object]) -> str:
    """The metadata member to trust: the top-level one, else DROA's `agent/` copy."""
    found = next((member for member in METADATA_MEMBERS if member in present), None)
    if found is None:
        raise not_valid(f"the archive has no {METADATA_MEMBER} at its top level")
    return found


def read_metadata(data: bytes) -> ModelMetadata:
    try:
        return parse_model_metadata_json(data)
    except ModelMetadataError as error:
        raise not_valid(error.message) from None


def check_stock_car_metadata(metadata: ModelMetadata, sizes: Mapping[str, int]) -> None:
    """An archive holding a `.pb` is for stock cars: its metadata is judged as the car will judge it."""
    if any(member in sizes for member in TENSORFLOW_MEMBERS):
        try:
            check_for_stock_car(metadata)
        except ModelMetadataError as error:
            raise not_valid(error.message) from None


def model_file(metadata: ModelMetadata, sizes: Mapping[str, int]) -> tuple[ModelKind, str]:
    """The model's kind and member; refuses archives with none, an empty one, or an ambiguous pair."""
    tensorflow = next((member for member in TENSORFLOW_MEMBERS if member in sizes), None)
    onnx = ONNX_MEMBER if ONNX_MEMBER in sizes else None
    # drem's own exports carry the same network twice: model.onnx (simulator, drem cars) and agent/model.pb
    # (stock cars), and say so in their metadata. Any other archive with both is ambiguous.
    drem_block = getattr(metadata, "drem", None)
    dual = isinstance(drem_block, dict) and drem_block.get("car_model_file") == tensorflow
    if tensorflow and onnx and not dual:
        raise not_valid(f"the archive holds both {onnx} and {tensorflow}; upload one model per archive")
    if not tensorflow and not onnx:
        raise not_valid("the archive has no model file: expected agent/model.pb (DeepRacer console) or "
                        "model.onnx (drem)")
    member = onnx or tensorflow
    assert member is not None
    if sizes[member] == 0:
        raise not_valid(f"the model file {member} is empty")
    return ("onnx" if onnx else "tensorflow"), member
