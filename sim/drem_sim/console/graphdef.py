"""A TensorFlow 1 frozen `GraphDef`, written without TensorFlow: the few protobuf messages it needs, hand-encoded.

Field numbers are TensorFlow's own (tensorflow/core/framework/{graph,node_def,attr_value,tensor,tensor_shape,
types,versions}.proto): GraphDef{node=1, versions=4}; NodeDef{name=1, op=2, input=3, attr=5 (map<string,
AttrValue>)}; AttrValue{list=1, s=2, i=3, f=4, b=5, type=6, shape=7, tensor=8}; AttrValue.ListValue{i=3};
TensorProto{dtype=1, tensor_shape=2, tensor_content=4}; TensorShapeProto{dim=2}; Dim{size=1}; VersionDef{producer=1}.
Protobuf's wire format is stable and simple (varints and length-delimited fields), which is why a hand encoder is
enough here and safer than pulling in TensorFlow (1.3 GB) to write a few hundred bytes of structure.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

DT_FLOAT = 1
DT_INT32 = 3
# The GraphDef producer version TensorFlow 1.15 writes (what the DeepRacer simapp's TF freezes with).
TF1_PRODUCER = 134

_VARINT, _FIXED32, _BYTES = 0, 5, 2


def _varint(value: int) -> bytes:
    if value < 0:
        value += 1 << 64  # protobuf encodes negative int64 as ten-byte two's complement
    out = bytearray()
    while True:
        low = value & 0x7F
        value >>= 7
        if value:
            out.append(low | 0x80)
        else:
            out.append(low)
            return bytes(out)


def _key(number: int, wire_type: int) -> bytes:
    return _varint((number << 3) | wire_type)


def _bytes_field(number: int, payload: bytes) -> bytes:
    return _key(number, _BYTES) + _varint(len(payload)) + payload


def _varint_field(number: int, value: int) -> bytes:
    return _key(number, _VARINT) + _varint(value)


def _shape(dims: list[int]) -> bytes:
    return b"".join(_bytes_field(2, _varint_field(1, dim) if dim != 0 else b"") for dim in dims)


def tensor(value: np.ndarray) -> bytes:
    """TensorProto of a float32 or int32 array (little-endian `tensor_content`, as TensorFlow writes it)."""
    array = np.ascontiguousarray(value)
    if array.dtype == np.float32:
        dtype = DT_FLOAT
    elif array.dtype == np.int32:
        dtype = DT_INT32
    else:
        raise TypeError(f"unsupported tensor dtype {array.dtype}")
    return (_varint_field(1, dtype) + _bytes_field(2, _shape(list(array.shape)))
            + _bytes_field(4, array.astype(array.dtype.newbyteorder("<")).tobytes()))


class Attr:
    """AttrValue encoders, one per kind a DeepRacer graph uses."""

    @staticmethod
    def type(dtype: int) -> bytes:
        return _varint_field(6, dtype)

    @staticmethod
    def string(text: str) -> bytes:
        return _bytes_field(2, text.encode())

    @staticmethod
    def boolean(flag: bool) -> bytes:
        return _varint_field(5, int(flag))

    @staticmethod
    def float(number: float) -> bytes:
        return _key(4, _FIXED32) + struct.pack("<f", number)

    @staticmethod
    def ints(values: list[int]) -> bytes:
        return _bytes_field(1, b"".join(_varint_field(3, v) for v in values))

    @staticmethod
    def shape(dims: list[int]) -> bytes:
        return _bytes_field(7, _shape(dims))

    @staticmethod
    def tensor(value: np.ndarray) -> bytes:
        return _bytes_field(8, tensor(value))


@dataclass
class Node:
    name: str
    op: str
    inputs: list[str] = field(default_factory=list)
    attrs: dict[str, bytes] = field(default_factory=dict)  # name -> encoded AttrValue

    def encode(self) -> bytes:
        body = _bytes_field(1, self.name.encode()) + _bytes_field(2, self.op.encode())
        body += b"".join(_bytes_field(3, name.encode()) for name in self.inputs)
        for key in sorted(self.attrs):  # map entries: key=1, value=2
            body += _bytes_field(5, _bytes_field(1, key.encode()) + _bytes_field(2, self.attrs[key]))
        return body


def graph_def(nodes: list[Node], producer: int = TF1_PRODUCER) -> bytes:
    return b"".join(_bytes_field(1, node.encode()) for node in nodes) + _bytes_field(4, _varint_field(1, producer))
