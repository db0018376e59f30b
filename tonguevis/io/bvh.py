"""BVH (Biovision Hierarchy) of EMA coils, read and write (Steiner et al. 2013, seed 004 §2-3).

Each coil is an independent ``ROOT`` named after the sensor, with position
channels (and optionally three rotation channels) and an ``End Site`` tip a unit
vector away; ``MOTION`` holds one line of channel values per frame.

Reading: sensors are the ROOT names; positions are the ROOT's position channel
values (absolute coordinates; the ROOT ``OFFSET``, which seed 004 sets to the
first frame, is used only for a ROOT without position channels).  BVH has no
unit: ``unit=`` says it (default ``"mm"``).  Rotation channels are returned raw,
(N, 3) in channel order (``metadata['rotation_orders']``), because EMA tools put
different things there (Carstens phi/theta, mngu0 rotation normals); pass
``rotations="quaternion"`` to read them as BVH Euler angles (degrees, intrinsic,
in channel order) and get (w, x, y, z) quaternions.  JOINTs below a ROOT are
parsed and ignored.  Positions stay in the file's frame unless ``axes=`` maps it.

Writing: a ROOT per sensor with ``OFFSET`` = its first valid position,
``CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation``
when the recording has quaternions (converted to XYZ Euler degrees) or raw BVH
rotations, else ``CHANNELS 3``.  Positions in ``unit`` (default mm), 6
decimals; dropped frames are re-inserted so frames are uniform in time;
missing samples are written as ``nan`` (our reader reads them back as NaN).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis._files import atomic_write
from tonguevis.io._common import (
    decode_text, format_rows, parse_axes, read_bytes, regrid_dropped_frames, unit_scale,
    unterminated_row_complete,
)
from tonguevis.io.recording import Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

_POS = {"xposition": 0, "yposition": 1, "zposition": 2}
_ROT = {"xrotation": "X", "yrotation": "Y", "zrotation": "Z"}


def sniff(head: bytes, path: Path) -> bool:
    return head.lstrip().upper().startswith(b"HIERARCHY")


class _Tokens:
    """Whitespace tokens of the HIERARCHY section with line numbers for errors."""

    def __init__(self, text: str, path):
        self.items = [(tok, n + 1) for n, line in enumerate(text.splitlines()) for tok in line.split()]
        self.i = 0
        self.path = path

    def next(self, what: str) -> tuple[str, int]:
        if self.i >= len(self.items):
            raise RecordingError(f"BVH hierarchy ends early: expected {what}", self.path)
        self.i += 1
        return self.items[self.i - 1]

    def expect(self, word: str) -> None:
        tok, line = self.next(repr(word))
        if tok.upper() != word.upper():
            raise RecordingError(f"line {line}: expected {word!r}, found {tok[:30]!r}", self.path)

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            return float(tok)
        except ValueError:
            raise RecordingError(f"line {line}: {what} {tok[:30]!r} is not a number", self.path) from None


def _parse_node(tokens: _Tokens, name: str, nodes: list, depth: int) -> None:
    """Parse ``{ OFFSET .. CHANNELS .. children }`` after a ROOT/JOINT name."""
    if depth > 200:
        raise RecordingError("BVH hierarchy nested too deeply", tokens.path)
    tokens.expect("{")
    tokens.expect("OFFSET")
    node = {"name": name, "offset": [tokens.number("OFFSET value") for _ in range(3)],
            "channels": [], "root": depth == 0}
    nodes.append(node)
    tok, line = tokens.next("CHANNELS or '}'")
    if tok.upper() == "CHANNELS":
        count = tokens.number("channel count")
        if not (0 <= count <= 64) or count != int(count):
            raise RecordingError(f"line {line}: impossible channel count {count}", tokens.path)
        for _ in range(int(count)):
            ch, ch_line = tokens.next("channel name")
            if ch.lower() not in _POS and ch.lower() not in _ROT:
                raise RecordingError(f"line {ch_line}: unknown BVH channel {ch[:30]!r}", tokens.path)
            node["channels"].append(ch.lower())
        tok, line = tokens.next("JOINT, End Site or '}'")
    while tok != "}":
        upper = tok.upper()
        if upper == "JOINT":
            child, _ = tokens.next("joint name")
            _parse_node(tokens, child, nodes, depth + 1)
        elif upper == "END":
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            for _ in range(3):
                tokens.number("End Site OFFSET value")
            tokens.expect("}")
        else:
            raise RecordingError(f"line {line}: expected JOINT, End Site or '}}', found {tok[:30]!r}", tokens.path)
        tok, line = tokens.next("'}'")


def read_bvh(path, unit: str = "mm", rotations: str = "raw", axes=None) -> Recording:
    """Read a BVH file of EMA coils; see the module docstring."""
    path = Path(path)
    text = decode_text(read_bytes(path), path)
    if not text.strip():
        raise RecordingError("empty file", path)
    if rotations not in ("raw", "quaternion"):
        raise RecordingError(f"rotations={rotations!r}: expected 'raw' or 'quaternion'", path)
    m = re.search(r"^\s*MOTION\s*$", text, re.MULTILINE | re.IGNORECASE)
    if m is None:
        raise RecordingError("no MOTION section", path)
    tokens = _Tokens(text[: m.start()], path)
    tokens.expect("HIERARCHY")
    nodes: list[dict] = []
    while tokens.i < len(tokens.items):
        tokens.expect("ROOT")
        name, _ = tokens.next("ROOT name")
        _parse_node(tokens, name, nodes, 0)
    if not nodes:
        raise RecordingError("hierarchy has no ROOT", path)
    motion_line = text[: m.start()].count("\n") + 1
    motion = text[m.end():]
    head = re.match(r"\s*Frames:\s*(\S+)\s*Frame\s+Time:\s*(\S+)", motion, re.IGNORECASE)
    if head is None:
        raise RecordingError(f"line {motion_line + 1}: expected 'Frames:' and 'Frame Time:' after MOTION", path)
    try:
        declared, frame_time = int(head.group(1)), float(head.group(2))
    except ValueError:
        raise RecordingError(f"bad Frames: {head.group(1)[:20]!r} or Frame Time: {head.group(2)[:20]!r}", path) from None
    if declared < 0 or not np.isfinite(frame_time) or frame_time <= 0:
        raise RecordingError(f"impossible Frames: {declared} or Frame Time: {frame_time}", path)
    n_channels = sum(len(node["channels"]) for node in nodes)
    words = motion[head.end():].split()
    if n_channels == 0:
        raise RecordingError("no node has channels", path)
    n_frames, partial = divmod(len(words), n_channels)
    if not partial and n_frames > 1 and not text.endswith(("\n", "\r")) and not unterminated_row_complete(
            words[len(words) - n_channels:], words[len(words) - 2 * n_channels:len(words) - n_channels]):
        partial = n_channels  # the last number was cut: the last frame is incomplete
        n_frames -= 1
    if partial:
        logger.warning("%s: dropped a partial last frame (%d of %d values; file truncated?)", path, partial, n_channels)
    if n_frames > declared:
        raise RecordingError(f"{n_frames} frames of data but 'Frames: {declared}'", path)
    if n_frames < declared:
        logger.warning("%s: 'Frames: %d' but only %d complete frames (file truncated?)", path, declared, n_frames)
    if n_frames == 0:
        raise RecordingError("no complete frame of motion data", path)
    try:
        values = np.array(words[: n_frames * n_channels], dtype=np.float64).reshape(n_frames, n_channels)
    except ValueError:
        bad = next(w for w in words if not _is_number(w))
        raise RecordingError(f"motion value {bad[:30]!r} is not a number", path) from None
    scale = unit_scale(unit, path)
    A = parse_axes(axes, path)
    sensors, orientations, orders = {}, {}, {}
    col = 0
    for node in nodes:
        cols = {ch: col + k for k, ch in enumerate(node["channels"])}
        col += len(node["channels"])
        if not node["root"]:
            continue
        if node["name"] in sensors:
            raise RecordingError(f"two ROOTs are named {node['name']!r}", path)
        xyz = np.empty((n_frames, 3))
        for ch, axis in _POS.items():
            xyz[:, axis] = values[:, cols[ch]] if ch in cols else node["offset"][axis]
        xyz *= scale
        xyz[~np.all(np.isfinite(xyz), axis=1)] = np.nan
        sensors[node["name"]] = xyz @ A.T
        rot = [ch for ch in node["channels"] if ch in _ROT]
        if rot:
            angles = values[:, [cols[ch] for ch in rot]]
            order = "".join(_ROT[ch] for ch in rot)
            orders[node["name"]] = order
            if rotations == "quaternion":
                orientations[node["name"]] = _euler_to_quaternion(angles, order, path)
            else:
                orientations[node["name"]] = angles
    metadata = {
        "format": "bvh",
        "file": str(path),
        "original_unit": unit,
        "frame": "file" if axes is None else "tonguevis",
        "axes": A.tolist(),
        "orientation_kind": "quaternion_wxyz" if rotations == "quaternion" else "bvh_rotation_channels_deg",
        "rotation_orders": orders,
        "dropped_frames": [],
        "truncated": bool(partial) or n_frames < declared,
    }
    rate = float(np.round(1.0 / frame_time, 6))
    return Recording(rate=rate, times=np.arange(n_frames) * frame_time, sensors=sensors,
                     orientations=orientations, metadata=metadata)


def _is_number(word: str) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def _euler_to_quaternion(angles: np.ndarray, order: str, path) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    if len(order) != 3 or len(set(order)) < 2:
        raise RecordingError(f"rotation channels {order} are not a BVH Euler triple", path)
    quats = np.full((len(angles), 4), np.nan)
    ok = np.all(np.isfinite(angles), axis=1)
    if ok.any():
        xyzw = Rotation.from_euler(order.upper(), angles[ok], degrees=True).as_quat()
        quats[ok] = xyzw[:, [3, 0, 1, 2]]
    return quats


def _quaternion_to_euler_xyz(quats: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    out = np.full((len(quats), 3), np.nan)
    ok = np.all(np.isfinite(quats), axis=1) & (np.linalg.norm(np.nan_to_num(quats), axis=1) > 0)
    if ok.any():
        out[ok] = Rotation.from_quat(quats[ok][:, [1, 2, 3, 0]]).as_euler("XYZ", degrees=True)
    return out


def write_bvh(rec: Recording, path, unit: str = "mm") -> None:
    """Write ``rec`` as a BVH of independent coils; see the module docstring."""
    path = Path(path)
    scale = unit_scale(unit, path)
    rec = regrid_dropped_frames(rec)
    n = rec.n_samples
    kind = rec.metadata.get("orientation_kind")
    orders = rec.metadata.get("rotation_orders", {})
    lines = ["HIERARCHY"]
    columns = []
    for name in rec.sensor_names:
        if re.search(r"[\s{}]", name) or not name:
            raise RecordingError(f"sensor name {name!r} cannot be a BVH ROOT name (no spaces or braces)", path)
        xyz = np.asarray(rec.sensors[name], dtype=float) / scale
        finite = np.flatnonzero(np.all(np.isfinite(xyz), axis=1))
        offset = xyz[finite[0]] if finite.size else np.zeros(3)
        orient = rec.orientations.get(name)
        angles, order = None, "XYZ"
        if orient is not None and kind == "quaternion_wxyz" and np.shape(orient) == (n, 4):
            angles = _quaternion_to_euler_xyz(np.asarray(orient, dtype=float))
        elif orient is not None and kind == "bvh_rotation_channels_deg" and np.shape(orient) == (n, 3):
            angles, order = np.asarray(orient, dtype=float), orders.get(name, "XYZ")
        channels = ["Xposition", "Yposition", "Zposition"]
        columns.append(xyz)
        if angles is not None:
            channels += [f"{axis}rotation" for axis in order]
            columns.append(angles)
        lines += [
            f"ROOT {name}", "{",
            "\tOFFSET\t" + "\t".join(f"{v:.6f}" for v in offset),
            f"\tCHANNELS {len(channels)} " + " ".join(channels),
            "\tEnd Site", "\t{", "\t\tOFFSET\t0.000000\t-1.000000\t0.000000", "\t}", "}",
        ]
    table = np.column_stack(columns) if columns else np.zeros((n, 0))
    lines += ["MOTION", f"Frames:\t{n}", f"Frame Time:\t{1.0 / rec.rate:.9f}"]
    lines += format_rows(table, "\t", nan="nan")
    text = "\n".join(lines) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


register_format(RecordingFormat(
    name="bvh",
    description="Biovision Hierarchy of EMA coils, one ROOT per sensor (seed 004)",
    extensions=(".bvh",),
    sniff=sniff,
    read=read_bvh,
    write=write_bvh,
    channel_name=str,
))
