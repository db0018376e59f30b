"""Small example files of every format, written here by independent test-side code.

Each ``make_<format>(folder)`` writes a file from a known truth and returns an
:class:`Example`: the path, the truth (sensor name -> (N, 3) metres, rate), the
reader options the file needs, the format name the registry must report and a
sensor-map value that names the first sensor.  The binary layouts (Carstens,
EST_Track, MVIEW) are written from the format descriptions, not with the
readers' code, so a reader bug cannot hide behind a matching writer bug.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tests.io.synthetic import make_recording
from tonguevis.io import write_recording


@dataclass
class Example:
    path: Path
    fmt: str
    truth: dict[str, np.ndarray]  # name -> (N, 3) metres, NaN where missing
    rate: float
    options: dict = field(default_factory=dict)
    map_value: object = None  # how a sensor map names the first sensor
    content_dispatch: bool = True  # False: the format has no magic (headerless Carstens)


def _truth(n_frames=12, n_sensors=4, seed=1, nan_at=(2, 1)):
    rng = np.random.default_rng(seed)
    xyz_mm = rng.uniform(-80, 80, size=(n_frames, n_sensors, 3)).round(3)
    if nan_at is not None and n_frames > nan_at[0] and n_sensors > nan_at[1]:
        xyz_mm[nan_at[0], nan_at[1]] = np.nan
    return xyz_mm


def make_ag501(folder: Path, version: int = 2, n_frames: int = 12, channels: int = 4) -> Example:
    xyz = _truth(n_frames, channels)
    values = np.zeros((n_frames, channels, 7), dtype="<f4")
    values[:, :, :3] = xyz
    values[:, :, 3] = 10.0  # phi
    values[:, :, 4] = -20.0  # theta
    values[:, :, 5] = 1.5  # rms
    lines = [f"AG50xDATA_V00{version}", "", f"NumberOfChannels={channels}", "SamplingFrequencyHz=250"]
    text_len = sum(len(x) + 1 for x in lines) + 8
    header_len = text_len + 2  # a NUL and a ^Z pad, as the AG501 writes
    lines[1] = f"{header_len:08d}"
    header = ("\n".join(lines) + "\n").encode() + b"\x00\x1a"
    assert len(header) == header_len
    path = folder / f"ag501_v{version}.pos"
    path.write_bytes(header + values.tobytes())
    truth = {f"CH{c + 1}": xyz[:, c] / 1000 for c in range(channels)}
    return Example(path, "carstens", truth, 250.0, map_value=1)


def make_ag500(folder: Path, n_frames: int = 6, channels: int = 12) -> Example:
    xyz = _truth(n_frames, channels)
    values = np.zeros((n_frames, channels, 7), dtype="<f4")
    values[:, :, :3] = xyz
    path = folder / "ag500.pos"
    path.write_bytes(values.tobytes())
    truth = {f"CH{c + 1}": xyz[:, c] / 1000 for c in range(channels)}
    return Example(path, "carstens", truth, 200.0, map_value=1, content_dispatch=False)


def _est_header(kind: str, names: list[str], n_frames: int, extra: str = "") -> str:
    lines = ["EST_File Track", f"DataType {kind}"] + (["ByteOrder 01"] if kind == "binary" else [])
    lines += [f"NumFrames {n_frames}", f"NumChannels {len(names)}", "NumAuxChannels 0",
              "EqualSpace 1", "BreaksPresent true", "CommentChar ;"]
    lines += [f"Channel_{i} {name}" for i, name in enumerate(names)]
    return "\n".join(lines) + "\n" + extra + "EST_Header_End\n"


def _est_values(n_frames=8, coils=("T1", "T2", "T3", "jaw")):
    xyz = _truth(n_frames, len(coils))
    names, cols = [], []
    for c, coil in enumerate(coils):
        for axis, suffix in enumerate(("px", "py", "pz")):
            names.append(f"{coil}_{suffix}")
            cols.append(xyz[:, c, axis])
        for suffix in ("ox", "oy", "oz"):
            names.append(f"{coil}_{suffix}")
            cols.append(np.full(n_frames, 0.5))
        names.append(f"{coil}_rms")
        cols.append(np.full(n_frames, 2.0))
    times = 0.005 + np.arange(n_frames) / 200.0
    return coils, xyz, names, times, np.column_stack(cols)


def make_est_ascii(folder: Path, n_frames: int = 8) -> Example:
    coils, xyz, names, times, values = _est_values(n_frames)
    rows = []
    for t, row in zip(times, values):
        cells = " ".join("nan" if np.isnan(v) else f"{v:.6f}" for v in row)
        rows.append(f"{t:.6f}\t1 \t{cells} \n")
    path = folder / "est_ascii.ema"
    path.write_text(_est_header("ascii", names, n_frames) + "".join(rows))
    truth = {coil: xyz[:, c] / 1000 for c, coil in enumerate(coils)}
    return Example(path, "est_track", truth, 200.0, map_value="T1")


def make_est_binary(folder: Path, n_frames: int = 8) -> Example:
    coils, xyz, names, times, values = _est_values(n_frames)
    frames = np.column_stack([times, np.ones(n_frames), values]).astype("<f4")
    path = folder / "est_binary.ema"
    path.write_bytes(_est_header("binary", names, n_frames).encode() + frames.tobytes())
    truth = {coil: xyz[:, c].astype(np.float32).astype(float) / 1000 for c, coil in enumerate(coils)}
    return Example(path, "est_track", truth, 200.0, map_value="T1")


def _mview_channels(n_frames=20):
    xyz = _truth(n_frames, 3, nan_at=(4, 2))
    names = ["TR", "TB", "TT"]
    audio = (0.1 * np.sin(np.arange(int(n_frames / 100 * 8000)) / 5.0)).astype(np.float32)
    words = [("sp", 0.0, 0.05), ("TA", 0.05, 0.18)]
    phones = [("sp", 0.0, 0.05), ("T", 0.05, 0.09), ("AA1", 0.09, 0.18)]
    return xyz, names, audio, words, phones


def make_mview_v5(folder: Path, n_frames: int = 20) -> Example:
    import scipy.io

    xyz, names, audio, words, phones = _mview_channels(n_frames)
    fields = ["NAME", "SRATE", "SIGNAL", "SOURCE", "SENTENCE", "WORDS", "PHONES"]
    arr = np.zeros((1, 1 + len(names)), dtype=[(f, "O") for f in fields])

    def tier(items):
        t = np.zeros((1, len(items)), dtype=[("LABEL", "O"), ("OFFS", "O")])
        for i, (label, s, e) in enumerate(items):
            t[0, i]["LABEL"] = label
            t[0, i]["OFFS"] = np.array([[s, e]])
        return t

    empty = np.zeros((1, 0))
    arr[0, 0] = ("AUDIO", np.array([[8000]], dtype=np.uint16), audio[:, None], "test", "Ta.", tier(words), tier(phones))
    for i, name in enumerate(names):
        signal = np.column_stack([xyz[:, i], np.full((n_frames, 3), 7.0)]).astype(np.float32)
        arr[0, i + 1] = (name, np.array([[100]], dtype=np.uint8), signal, empty, empty, empty, empty)
    path = folder / "mview_v5.mat"
    scipy.io.savemat(str(path), {"take1": arr}, do_compression=True)
    truth = {name: xyz[:, i].astype(np.float32).astype(float) / 1000 for i, name in enumerate(names)}
    return Example(path, "mview", truth, 100.0, map_value="TR")


def _write_matlab73_header(path: Path) -> None:
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 ."
    header = text.ljust(116, b" ") + b"\x00" * 8 + struct.pack("<H", 0x0200) + b"IM"
    with open(path, "r+b") as f:
        f.write(header.ljust(512, b"\x00"))


def make_mview_v73(folder: Path, n_frames: int = 20) -> Example:
    """A v7.3 (HDF5) MVIEW file laid out as MATLAB writes struct arrays (references into #refs#)."""
    import h5py

    xyz, names, audio, words, phones = _mview_channels(n_frames)
    path = folder / "mview_v73.mat"
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        counter = [0]

        def put(value):
            counter[0] += 1
            key = f"r{counter[0]}"
            if isinstance(value, str):
                ds = refs.create_dataset(key, data=np.array([[ord(c)] for c in value], dtype=np.uint16))
                ds.attrs["MATLAB_class"] = np.bytes_("char")
            elif isinstance(value, list):  # a struct array of dicts
                g = refs.create_group(key)
                g.attrs["MATLAB_class"] = np.bytes_("struct")
                for fld in value[0]:
                    g.create_dataset(fld, data=np.array([[put(item[fld])] for item in value], dtype=h5py.ref_dtype))
                return g.ref
            elif np.size(value) == 0:  # MATLAB stores [] as its dimensions, flagged MATLAB_empty
                ds = refs.create_dataset(key, data=np.array(np.shape(value), dtype=np.uint64))
                ds.attrs["MATLAB_class"] = np.bytes_("double")
                ds.attrs["MATLAB_empty"] = np.uint8(1)
            else:
                ds = refs.create_dataset(key, data=np.asarray(value, dtype=float).T)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
            return ds.ref

        def tier(items):
            return [{"LABEL": label, "OFFS": np.array([[s, e]])} for label, s, e in items]

        channels = [{"NAME": "AUDIO", "SRATE": np.array([[8000.0]]), "SIGNAL": audio[:, None].astype(float),
                     "SENTENCE": "Ta.", "WORDS": tier(words), "PHONES": tier(phones)}]
        for i, name in enumerate(names):
            signal = np.column_stack([xyz[:, i], np.full((n_frames, 3), 7.0)])
            channels.append({"NAME": name, "SRATE": np.array([[100.0]]), "SIGNAL": signal, "SENTENCE": "",
                             "WORDS": np.zeros((0, 0)), "PHONES": np.zeros((0, 0))})
        group = f.create_group("take1")
        group.attrs["MATLAB_class"] = np.bytes_("struct")
        for fld in channels[0]:
            group.create_dataset(fld, data=np.array([[put(ch[fld])] for ch in channels], dtype=h5py.ref_dtype))
    _write_matlab73_header(path)
    truth = {name: xyz[:, i] / 1000 for i, name in enumerate(names)}
    return Example(path, "mview", truth, 100.0, map_value="TR")


def _written(folder: Path, name: str, fmt: str, map_value, **kw) -> Example:
    rec = make_recording(n=15, names=("S1", "S2", "S4"), audio_rate=4000.0, seed=3)
    path = folder / name
    write_recording(rec, path, **kw)
    return Example(path, fmt, dict(rec.sensors), rec.rate, map_value=map_value)


def make_ndi(folder: Path) -> Example:
    return _written(folder, "ndi.tsv", "ndi_wave", 1)


def make_bvh(folder: Path) -> Example:
    return _written(folder, "coils.bvh", "bvh", "S1")


def make_csv_wide(folder: Path) -> Example:
    return _written(folder, "wide.csv", "csv", "S1")


def make_csv_long(folder: Path) -> Example:
    return _written(folder, "long.csv", "csv", "S1", layout="long")


def _optispeech_cell(v) -> str:
    return "" if not np.isfinite(v) else repr(float(v))


def make_optispeech_markers(folder: Path, n_frames: int = 12) -> Example:
    """Opti-Speech 1 marker layout: Unity x right, y up, z forward (mm), 10 ms clock."""
    xyz = _truth(n_frames, 3)  # ours: x anterior, y left, z up (mm)
    unity = np.stack([-xyz[..., 1], xyz[..., 2], xyz[..., 0]], axis=-1)
    header = ["timestamp"] + ["Marker Number", "Qw", "Qx", "Qy", "Qz", "X", "Y", "Z"] * 6 + ["Landmark Number", "X", "Y", "Z"]
    lines = ["\t".join(header)]
    for k in range(n_frames):
        row = [str(10 * k + 3)]
        row += ["1", "0", "0", "0", "0", "-100", "0", "-100", "2", "0", "0", "0", "0", "100", "0", "-100"]
        for j, marker in enumerate((3, 4, 5)):
            row += [str(marker), "0", "0", "0", "0"] + [_optispeech_cell(v) for v in unity[k, j]]
        row += ["10", "0", "0", "0", "0", "-3.1E+28", "3.3E+28", "-4.4E+28"]  # the unused probe slot
        row += ["0", "1.5", "-87.7", "5.4"]
        lines.append("\t".join(row))
    path = folder / "sweep_markers.tsv"
    path.write_text("\n".join(lines) + "\n")
    truth = {name: xyz[:, j] / 1000 for j, name in enumerate(("TT", "TB", "TR"))}
    return Example(path, "optispeech", truth, 100.0, map_value="TT")


def make_optispeech_sensors(folder: Path, n_frames: int = 12) -> Example:
    """Opti-Speech 2 sensor layout: the file's X, Y, Z are Unity's y (up), z (forward), x (right)."""
    xyz = _truth(n_frames, 3, seed=4)
    file_xyz = np.stack([xyz[..., 2], xyz[..., 0], -xyz[..., 1]], axis=-1)
    header = ["timestamp", "Placeholder1", "Placeholder2"]
    header += ["Sensor", "Status", "X", "Y", "Z", "Qw", "Qx", "Qy", "Qz"] * 3
    lines = ["\t".join(header)]
    for k in range(n_frames):
        row = [str(10 * k), "0", "0"]
        for j, sensor in enumerate((4, 6, 9)):
            status = "55" if np.all(np.isfinite(file_xyz[k, j])) else "119"
            row += [str(sensor), status] + [_optispeech_cell(v) for v in file_xyz[k, j]] + ["1", "0", "0", "0"]
        lines.append("\t".join(row))
    path = folder / "sweep_sensors.tsv"
    path.write_text("\n".join(lines) + "\n")
    truth = {name: xyz[:, j] / 1000 for j, name in enumerate(("TT", "TR", "JAW"))}
    return Example(path, "optispeech", truth, 100.0, map_value="TT")


MAKERS = {
    "optispeech_markers": make_optispeech_markers,
    "optispeech_sensors": make_optispeech_sensors,
    "ag501_v1": lambda d: make_ag501(d, version=1),
    "ag501_v2": make_ag501,
    "ag501_v3": lambda d: make_ag501(d, version=3),
    "ag500": make_ag500,
    "est_ascii": make_est_ascii,
    "est_binary": make_est_binary,
    "mview_v5": make_mview_v5,
    "mview_v73": make_mview_v73,
    "ndi_wave": make_ndi,
    "bvh": make_bvh,
    "csv_wide": make_csv_wide,
    "csv_long": make_csv_long,
}
