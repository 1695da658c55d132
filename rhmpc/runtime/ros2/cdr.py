"""Plain CDR, the encoding ROS 2 writes, built from each message's own definition.

A ROS 2 node on DDS writes a message as plain CDR (OMG's XCDR version 1), little-endian, after
the 4-byte encapsulation header ``00 01 00 00`` (CDR_LE): each field in its order, a primitive
aligned to its own size (at most 8) from the first byte after the header, a string as a
``uint32`` length counting its terminating NUL then its bytes and the NUL, a sequence as a
``uint32`` count then its elements (OMG DDS-XTypes 1.3, 7.4.3.5; ROS 2's
``rosidl_typesupport_fastrtps`` and ``rmw_cyclonedds`` write the same layout).

:func:`codec` reads a message type's fields (a ``cyclonedds`` IDL dataclass: its type hints
name the primitives, strings, sequences and nested messages) once and returns its encoder and
decoder: each is a flat list of steps, a few microseconds for a joint state where
``cyclonedds``' generic serializer takes about a hundred, which matters at 2 kHz. A decoder
raises :class:`CdrError` for bytes that do not hold a message of its type.

This module imports no ``cyclonedds``: it reads the type hints only.
"""

from __future__ import annotations

import dataclasses
import struct
import typing
from collections.abc import Callable

__all__ = ["CDR_LE", "CdrError", "Codec", "codec"]

#: The encapsulation header of plain CDR, little-endian (RTPS 2.5, 10.5: CDR_LE).
CDR_LE = b"\x00\x01\x00\x00"
#: The primitives of the messages: IDL name → ``struct`` code.
PRIMITIVES = {"int8": "b", "uint8": "B", "byte": "B", "int16": "h", "uint16": "H", "int32": "i",
              "uint32": "I", "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}
_COUNT = struct.Struct("<I")


class CdrError(ValueError):
    """Bytes that do not hold a message of the type."""


class _Reader:
    """Bytes being decoded and the position in them (0: the first byte after the header)."""

    __slots__ = ("data", "pos")

    def __init__(self, data: bytes) -> None:
        self.data, self.pos = memoryview(data)[len(CDR_LE):], 0

    def align(self, size: int) -> None:
        self.pos += -self.pos % size

    def count(self, least: int) -> int:
        """A sequence's or a string's length, checked against the bytes left (each element
        takes at least ``least`` bytes)."""
        self.align(4)
        (n,) = _COUNT.unpack_from(self.data, self.pos)
        self.pos += 4
        if n * least > len(self.data) - self.pos:
            raise CdrError(f"a length of {n} beyond the message's end")
        return n


Encode = Callable[[bytearray, object], None]
Decode = Callable[[_Reader], object]


def _pad(out: bytearray, size: int) -> None:
    """Zeros up to the next multiple of ``size`` from the first byte after the header."""
    pad = (len(CDR_LE) - len(out)) % size
    if pad:
        out += bytes(pad)


def _primitive(code: str) -> tuple[Encode, Decode, int]:
    one = struct.Struct("<" + code)

    def encode(out: bytearray, value) -> None:
        _pad(out, one.size)
        out += one.pack(value)

    def decode(reader: _Reader):
        reader.align(one.size)
        (value,) = one.unpack_from(reader.data, reader.pos)
        reader.pos += one.size
        return value

    return encode, decode, one.size


def _encode_str(out: bytearray, value: str) -> None:
    data = value.encode()
    _pad(out, 4)
    out += _COUNT.pack(len(data) + 1) + data + b"\0"


def _decode_str(reader: _Reader) -> str:
    n = reader.count(1)
    if n == 0 or reader.data[reader.pos + n - 1] != 0:
        raise CdrError("a string without its terminating NUL")
    text = bytes(reader.data[reader.pos:reader.pos + n - 1]).decode()
    reader.pos += n
    return text


def _sequence_of_primitives(code: str) -> tuple[Encode, Decode, int]:
    size = struct.calcsize(code)

    def encode(out: bytearray, values) -> None:
        _pad(out, 4)
        out += _COUNT.pack(len(values))
        if len(values):
            _pad(out, size)
            out += struct.pack(f"<{len(values)}{code}", *values)

    def decode(reader: _Reader) -> list:
        n = reader.count(size)
        if not n:
            return []
        reader.align(size)
        values = list(struct.unpack_from(f"<{n}{code}", reader.data, reader.pos))
        reader.pos += n * size
        return values

    return encode, decode, 4


def _sequence(element: tuple[Encode, Decode, int]) -> tuple[Encode, Decode, int]:
    encode_one, decode_one, least = element

    def encode(out: bytearray, values) -> None:
        _pad(out, 4)
        out += _COUNT.pack(len(values))
        for value in values:
            encode_one(out, value)

    def decode(reader: _Reader) -> list:
        return [decode_one(reader) for _ in range(reader.count(least))]

    return encode, decode, 4


def _steps(hint) -> tuple[Encode, Decode, int]:
    """The encoder, the decoder and the least size in bytes of a field of type ``hint``."""
    if hint is str:
        return _encode_str, _decode_str, 5
    if dataclasses.is_dataclass(hint):
        c = codec(hint)
        return c.encode_into, c.decode_from, c.least
    if typing.get_origin(hint) is typing.Annotated:
        _, marker = typing.get_args(hint)
        if isinstance(marker, str) and marker in PRIMITIVES:
            return _primitive(PRIMITIVES[marker])
        subtype = getattr(marker, "subtype", None)
        if type(marker).__name__ == "sequence" and subtype is not None:
            if typing.get_origin(subtype) is typing.Annotated and \
                    typing.get_args(subtype)[1] in PRIMITIVES:
                return _sequence_of_primitives(PRIMITIVES[typing.get_args(subtype)[1]])
            return _sequence(_steps(subtype))
    raise TypeError(f"no plain-CDR rule for a field of type {hint!r}")


@dataclasses.dataclass(frozen=True)
class Codec:
    """A message type's plain-CDR encoder and decoder (:func:`codec`)."""

    cls: type
    encoders: tuple[Encode, ...]
    decoders: tuple[Decode, ...]
    names: tuple[str, ...]
    least: int  # bytes it takes at the least (alignment aside)

    def encode_into(self, out: bytearray, message) -> None:
        for name, encode in zip(self.names, self.encoders, strict=True):
            encode(out, getattr(message, name))

    def decode_from(self, reader: _Reader):
        return self.cls(*[decode(reader) for decode in self.decoders])

    def encode(self, message) -> bytes:
        """The bytes of ``message``, the encapsulation header first."""
        out = bytearray(CDR_LE)
        self.encode_into(out, message)
        return bytes(out)

    def decode(self, data: bytes):
        """The message of ``data`` (the encapsulation header first, CDR_LE);
        :class:`CdrError` for bytes that do not hold one."""
        if bytes(data[:2]) != CDR_LE[:2]:
            raise CdrError(f"encapsulation {bytes(data[:4]).hex()}, not plain CDR, little-endian")
        try:
            return self.decode_from(_Reader(data))
        except (struct.error, UnicodeDecodeError, IndexError) as exc:
            raise CdrError(str(exc)) from None


_CODECS: dict[type, Codec] = {}


def codec(cls: type) -> Codec:
    """The codec of the message dataclass ``cls`` (made once, from its fields' type hints)."""
    if cls not in _CODECS:
        hints = typing.get_type_hints(cls, include_extras=True)
        names = tuple(f.name for f in dataclasses.fields(cls))
        steps = [_steps(hints[name]) for name in names]
        _CODECS[cls] = Codec(cls, tuple(s[0] for s in steps), tuple(s[1] for s in steps), names,
                             max(sum(s[2] for s in steps), 1))
    return _CODECS[cls]
