"""A small, defensive reader of MATLAB MAT v5 files (what MVIEW files need).

Why not ``scipy.io.loadmat``: on damaged files it can crash the interpreter
(a segmentation fault inside its compiled reader, found by our fuzz tests).
This reader checks every length against the bytes actually present, limits
nesting and decompressed size, and raises :class:`RecordingError` instead.

Values come back as: numeric and logical arrays -> ndarray shaped as in
MATLAB (column-major data reshaped with ``order="F"``); char arrays -> str
(rows joined by newlines); struct arrays -> :class:`MatStruct` (a list of
dicts, one per element, with the MATLAB ``shape``); cell arrays -> list;
classes we do not need (sparse, objects, function handles) -> None.
Layout reference: MathWorks, "MAT-File Format" (version 5 section).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError

HEADER_BYTES = 128
MAX_DEPTH = 32
MAX_DECOMPRESSED = 1 << 30  # bytes; MVIEW files are a few MB

# MAT data types (mi*) -> NumPy element types (little-endian; byte-swapped for "MI" files).
_MI_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8", 12: "i8", 13: "u8",
              16: "u1", 17: "u2", 18: "u4"}
MI_INT8, MI_INT32, MI_UINT32, MI_MATRIX, MI_COMPRESSED = 1, 5, 6, 14, 15
MX_CELL, MX_STRUCT, MX_OBJECT, MX_CHAR, MX_SPARSE = 1, 2, 3, 4, 5
# mx numeric classes -> NumPy types (MATLAB may store e.g. a double array as miUINT8 to save space).
_CLASS_DTYPES = {6: "f8", 7: "f4", 8: "i1", 9: "u1", 10: "i2", 11: "u2", 12: "i4", 13: "u4", 14: "i8", 15: "u8"}


class MatStruct(list):
    """A MATLAB struct array: a list of {field: value} dicts in column-major order."""

    def __init__(self, elements, fields, shape):
        super().__init__(elements)
        self.fields = list(fields)
        self.shape = tuple(shape)


class _Reader:
    def __init__(self, data: bytes, path, byte_order: str):
        self.data, self.path, self.bo = data, path, byte_order

    def fail(self, message: str):
        raise RecordingError(f"damaged MAT v5 file: {message}", self.path)

    def tag(self, buf: bytes, pos: int) -> tuple[int, int, int, int]:
        """(type, size, data start, next element position) of the element at ``pos``."""
        if pos + 8 > len(buf):
            self.fail(f"element tag at byte {pos} runs past the end")
        first, second = struct.unpack_from(self.bo + "II", buf, pos)
        if first >> 16:  # small data element: size in the upper half, data in the tag's second word
            return first & 0xFFFF, first >> 16, pos + 4, pos + 8
        mtype, size = first, second
        start = pos + 8
        if start + size > len(buf):
            self.fail(f"element at byte {pos} claims {size} bytes, only {len(buf) - start} remain")
        padded = size if mtype == MI_COMPRESSED else (size + 7) // 8 * 8
        return mtype, size, start, min(start + padded, len(buf))

    def numbers(self, buf: bytes, pos: int, what: str) -> tuple[np.ndarray, int]:
        mtype, size, start, nxt = self.tag(buf, pos)
        if mtype not in _MI_DTYPES:
            self.fail(f"{what} has data type {mtype}, not a number type")
        dtype = np.dtype(_MI_DTYPES[mtype]).newbyteorder(self.bo)
        if size % dtype.itemsize:
            self.fail(f"{what} size {size} is not a whole number of {dtype.itemsize}-byte values")
        return np.frombuffer(buf, dtype=dtype, count=size // dtype.itemsize, offset=start), nxt

    def matrix(self, buf: bytes, pos: int, depth: int):
        """(name, value, next position) of the miMATRIX element at ``pos``."""
        if depth > MAX_DEPTH:
            self.fail("arrays nested too deeply")
        mtype, size, start, nxt = self.tag(buf, pos)
        if mtype != MI_MATRIX:
            self.fail(f"expected an array (type 14) at byte {pos}, found type {mtype}")
        if size == 0:
            return "", np.zeros((0, 0)), nxt
        body = buf[start:start + size]
        flags, p = self.numbers(body, 0, "array flags")
        if flags.size < 1:
            self.fail("array flags missing")
        cls, complex_, logical = int(flags[0]) & 0xFF, bool(int(flags[0]) & 0x800), bool(int(flags[0]) & 0x200)
        dims, p = self.numbers(body, p, "dimensions")
        if dims.size < 2 or np.any(dims < 0):
            self.fail(f"impossible array dimensions {dims.tolist()}")
        shape = tuple(int(d) for d in dims)
        count = int(np.prod(shape, dtype=np.int64))
        name_bytes, p = self.numbers(body, p, "array name")
        name = name_bytes.tobytes().decode("latin-1")
        if cls == MX_CHAR and self.tag(body, p)[0] == 16:  # UTF-8 text: count characters, not bytes
            text_bytes, p = self.numbers(body, p, f"text of {name or 'an array'}")
            codes = np.array([ord(c) for c in text_bytes.tobytes().decode("utf-8", errors="replace")])
            if codes.size != count:
                self.fail(f"char array {name or '?'} of shape {shape} holds {codes.size} characters")
            return name, _chars(codes, shape), nxt
        if cls in _CLASS_DTYPES or cls == MX_CHAR:
            real, p = self.numbers(body, p, f"data of {name or 'an array'}")
            if complex_:
                imag, p = self.numbers(body, p, f"imaginary data of {name or 'an array'}")
                if imag.size != real.size:
                    self.fail("real and imaginary parts differ in length")
                real = real + 1j * imag
            if real.size != count:
                self.fail(f"array {name or '?'} of shape {shape} holds {real.size} values")
            if cls == MX_CHAR:
                return name, _chars(real, shape), nxt
            target = np.dtype(bool if logical else _CLASS_DTYPES[cls])
            if complex_:
                target = np.result_type(target, np.complex64)
            return name, real.astype(target).reshape(shape, order="F"), nxt
        if cls == MX_CELL:
            return name, [self.matrix(body, p2, depth + 1)[1] for p2 in self._children(body, p, count)], nxt
        if cls == MX_STRUCT:
            lengths, p = self.numbers(body, p, "field name length")
            if lengths.size != 1 or not 0 < int(lengths[0]) <= 4096:
                self.fail("impossible struct field name length")
            names, p = self.numbers(body, p, "field names")
            width = int(lengths[0])
            raw = names.tobytes()
            fields = [raw[i:i + width].split(b"\0")[0].decode("latin-1") for i in range(0, len(raw), width)]
            children = self._children(body, p, count * len(fields))
            values = [self.matrix(body, c, depth + 1)[1] for c in children]
            elements = [dict(zip(fields, values[i * len(fields):(i + 1) * len(fields)])) for i in range(count)]
            return name, MatStruct(elements, fields, shape), nxt
        return name, None, nxt  # sparse, objects, function handles: not needed here

    def _children(self, body: bytes, pos: int, count: int) -> list[int]:
        """Start positions of ``count`` consecutive miMATRIX children (checked to exist)."""
        starts = []
        for _ in range(count):
            if pos >= len(body):
                self.fail(f"array announces {count} elements, found {len(starts)}")
            starts.append(pos)
            pos = self.tag(body, pos)[3]
        return starts


def _chars(codes: np.ndarray, shape: tuple[int, ...]) -> str:
    grid = codes.reshape(shape, order="F") if len(shape) == 2 else codes.reshape(-1, 1)
    rows = ["".join(chr(int(c)) if 0 <= int(c) < 0x110000 else "?" for c in row) for row in grid]
    return "\n".join(rows)


def read_mat5(path: str | Path) -> dict[str, object]:
    """All variables of a MAT v5 file: {name: value} (see the module docstring)."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) < HEADER_BYTES:
        raise RecordingError("MAT file shorter than its 128-byte header", path)
    indicator = data[126:128]
    if indicator == b"IM":
        bo = "<"
    elif indicator == b"MI":
        bo = ">"
    else:
        raise RecordingError(f"MAT v5 header has no endian indicator (found {indicator!r})", path)
    reader = _Reader(data, path, bo)
    variables: dict[str, object] = {}
    pos = HEADER_BYTES
    while pos + 8 <= len(data):
        mtype, size, start, nxt = reader.tag(data, pos)
        if mtype == MI_COMPRESSED:
            inflater = zlib.decompressobj()
            try:
                inner = inflater.decompress(data[start:start + size], MAX_DECOMPRESSED)
            except zlib.error as exc:
                reader.fail(f"compressed variable at byte {pos} does not inflate ({exc})")
            if inflater.unconsumed_tail:
                reader.fail(f"compressed variable at byte {pos} inflates past {MAX_DECOMPRESSED} bytes")
            if not inflater.eof:
                reader.fail(f"compressed variable at byte {pos} is cut short")
            name, value, _ = reader.matrix(inner, 0, 0)
        elif mtype == MI_MATRIX:
            name, value, _ = reader.matrix(data, pos, 0)
        else:
            reader.fail(f"unexpected top-level element of type {mtype} at byte {pos}")
        variables[name] = value
        pos = nxt
    return variables
