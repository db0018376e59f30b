"""A fast path for large, well-formed text tables of numbers (pyarrow's C++ CSV parser).

The readers' own parsing (:func:`tonguevis.io._common.parse_number_table`) turns
every cell into a Python float: an 80 MB NDI Wave export of 30 minutes (18
million cells) took 9-10 s.  :func:`plain_table` hands the body of a table to
pyarrow instead (about 1 s for the same file), but only when nothing in
it needs the careful path: ASCII, ``\\n`` or ``\\r\\n`` line ends, every row as
wide as the first, cells made of digits, ``. + - e E`` or empty (NaN).  Anything
else (a wrong field count, a stray letter, whitespace, a short last line, a
lone ``\\r``) returns None and the reader parses the file as before, which
names the line and the problem.  Within that character set pyarrow accepts a
cell exactly when Python's ``float`` does and gives the same bits (checked
over every cell of up to four such characters and 20,000 random longer ones;
a test compares the two paths on whole files).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Bytes a body may hold for the fast path (numbers, empty cells, separators, line ends).
NUMBER_BYTES = b"0123456789.+-eE\r\n"


@dataclass
class PlainTable:
    """A table parsed by :func:`plain_table`.

    header : the first line, decoded, without its line end.
    first_data_line : 1-based line number of the first data row.
    values : (R, C) float64, empty cells NaN; C is the first data row's field count.
    last_lines : [(1-based line number, text)] of the last two non-blank data lines (for the
        reader's end checks; one if there is one data row).
    ended : whether the file ends with a line end.
    """

    header: str
    first_data_line: int
    values: np.ndarray
    last_lines: list[tuple[int, str]]
    ended: bool


def plain_table(data: bytes, delimiter: str = "\t") -> PlainTable | None:
    """The table in ``data`` (header line, then rows of numbers), or None when the fast path does not apply.

    None whenever pyarrow is missing or the file has anything unusual (see the module
    docstring): the caller then parses it the careful way, with its own errors.
    """
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:  # an optional speed-up: the careful path reads the same files
        return None
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if b"\x00" in data or not data.isascii():
        return None
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        return None  # lone CRs are line ends to the careful path and not to pyarrow
    newline = data.find(b"\n")
    if newline < 0:
        return None
    header = data[:newline].decode("ascii").rstrip("\r")
    if not header.strip():
        return None  # blank lines before the header: the careful path numbers the lines
    body_start = newline + 1
    if data[body_start:].translate(None, NUMBER_BYTES + delimiter.encode()):
        return None
    # Blank lines are skipped (as the careful path does); the first data row's line number counts them.
    lead = len(data) - body_start - len(data[body_start:].lstrip(b"\r\n"))
    stripped_lead = data[body_start:body_start + lead]
    first_data_line = 2 + stripped_lead.count(b"\n")
    first_end = data.find(b"\n", body_start + lead)
    first_row = data[body_start + lead:first_end if first_end >= 0 else len(data)].rstrip(b"\r")
    if not first_row:
        return None
    n_fields = first_row.count(delimiter.encode()) + 1
    names = [f"c{k}" for k in range(n_fields)]
    rows = data.count(b"\n", body_start) + 1  # at least the data rows
    values = np.empty((rows, n_fields))
    done = 0
    try:
        # Streamed block by block into one array (with the system allocator, which gives the memory
        # back): the whole Arrow table beside the array cost 280 MB more at the peak for 30 minutes.
        reader = pacsv.open_csv(
            pa.BufferReader(pa.py_buffer(data).slice(body_start)),
            read_options=pacsv.ReadOptions(column_names=names, block_size=1 << 22),
            parse_options=pacsv.ParseOptions(delimiter=delimiter, quote_char=False, double_quote=False,
                                             escape_char=False, newlines_in_values=False, ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(column_types={name: pa.float64() for name in names},
                                                 null_values=[""], strings_can_be_null=False,
                                                 quoted_strings_can_be_null=False),
            memory_pool=pa.system_memory_pool())
        for batch in reader:
            count = batch.num_rows
            for k in range(n_fields):
                values[done:done + count, k] = batch.column(k).to_numpy(zero_copy_only=False)  # empty: NaN
            done += count
    except (pa.ArrowInvalid, pa.ArrowException):
        return None  # a row of another width, a malformed number: the careful path says which
    values = values[:done]
    if np.isnan(values).all(axis=1).any():
        return None  # a line of separators only: blank to the careful path, which skips it
    last_lines = _last_lines(data, body_start, min(2, len(values)))
    return PlainTable(header, first_data_line, values, last_lines, data.endswith(b"\n"))


def _last_lines(data: bytes, start: int, count: int) -> list[tuple[int, str]]:
    """[(line number, text)] of the last ``count`` non-blank lines of ``data[start:]``, in file order."""
    out: list[tuple[int, str]] = []
    end = len(data)
    while len(out) < count and end > start:
        begin = max(start, data.rfind(b"\n", start, end) + 1)
        line = data[begin:end].rstrip(b"\r\n")
        if line:
            out.insert(0, (data.count(b"\n", 0, begin) + 1, line.decode("ascii")))
        end = begin - 1 if begin > start else start
    return out
