"""ParaView export of a motion: the mesh once, every frame's fields in one HDF5 file (XDMF 3).

The old export wrote one ``.vtu`` per frame, mesh and all (about 210 KB a frame:
38 GB for a 30-minute recording).  Here the mesh is written once and each
exported frame adds only its displacement, in float32 rounded to
:data:`DISPLACEMENT_QUANTUM` (2⁻¹⁸ m = 3.8 µm, so at most 1.9 µm off: a
hundredth of EMA's own accuracy of a few tenths of a millimetre) and stored with HDF5's shuffle + deflate filters, which
every HDF5 reader (ParaView's included) undoes by itself: the rounding empties
the low mantissa bits that plain float32 noise would fill, so a frame of the
whole 1,802-node tongue takes about 7.5 KB instead of 22, written in HDF5
1.10's file format (which indexes a one-chunk dataset without a B-tree).  Frames are reconstructed from q chunk by chunk
(:meth:`Motion.iter_displacements`), so memory does not grow with the recording either.

Two files, in the layout meshio's XDMF time-series writer makes (so
``meshio.xdmf.TimeSeriesReader`` and ParaView's XDMF readers open it):

``NAME.xdmf``
    the mesh grid (rest positions; tetrahedra, or the surface triangles) and a
    temporal collection with one grid per exported frame: its time in seconds
    and a ``displacement`` attribute (metres, per node) pointing into NAME.h5;
    ``Information`` elements say the units and the frame of reference.
``NAME.h5``
    ``/mesh/points`` (n, 3) float64 m, ``/mesh/cells`` (c, 4 or 3) int32,
    ``/mesh/node_ids`` (n,) the model's node numbers; ``/displacement/000000``,
    ... (n, 3) float32 m, one dataset per exported frame; ``/times`` (F',) s,
    ``/frames`` (F',) the motion's frame numbers, ``/jaw_offset`` (F', 3) m.

In ParaView: open NAME.xdmf (the XDMF3 reader), *Warp By Vector* with
``displacement`` gives the moving tongue, colour by it for the magnitude.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from tonguevis._files import atomic_write
from tonguevis._progress import ProgressCallback, report

#: Displacements are rounded to this many metres (a power of two, so the rounding is exact in
#: float32 and leaves zero low bits for the deflate filter): 2⁻¹⁸ m = 3.8 µm.  Per frame of the
#: whole tongue: 2⁻²⁰ m 11.6 KB, 2⁻¹⁸ m 9.7 KB, unrounded 22 KB (deflate alone gains 4 %).
DISPLACEMENT_QUANTUM = 2.0 ** -18
#: zlib level of HDF5's deflate filter: level 1 gets within 3 % of level 4's size, faster.
DEFLATE_LEVEL = 1

_FIELD = {"head": "displacement = position in the head frame minus rest position (the tongue's deformation plus "
                  "the jaw's translation, /jaw_offset in the .h5)",
          "jaw": "displacement = the tongue's own deformation (jaw frame)"}


def write_xdmf(motion, path, surface_only: bool = False, stride: int = 1, frames: slice | np.ndarray | None = None,
               frame: str = "head", extra_fields: Callable[[np.ndarray], dict] | None = None,
               chunk: int | None = None, progress: ProgressCallback | None = None) -> Path:
    """Write ``motion`` to ``path`` (NAME.xdmf) and NAME.h5 beside it; returns the .xdmf path.

    surface_only : the boundary triangles and their nodes only (41 % of the bytes on our tongue).
    stride : every ``stride``-th frame (of ``frames``, a slice or index array, default all).
    frame : "head" (the tongue carried by ``motion.jaw_offset``; the default, as every export
        for people) or "jaw" (as simulated); see :mod:`tonguevis.sim.reference`.
    extra_fields : ``extra_fields(indices)`` -> {name: (c, n) or (c, n, 3) array} more point
        data for the frames ``indices`` (c,) of a chunk, on the exported nodes (e.g. the app's
        energy density, J/m³); written as float32 like the displacement.
    Both files are written under temporary names and renamed when complete.
    """
    import h5py

    from tonguevis.sim.reference import check_reference, describe, jaw_moves, tongue_offset

    check_reference(frame)
    stride = int(stride)
    if stride < 1:
        raise ValueError(f"the frame stride must be at least 1, got {stride}")
    path = Path(path)
    if path.suffix.lower() != ".xdmf":
        path = path.with_suffix(".xdmf")
    h5_path = path.with_suffix(".h5")
    path.parent.mkdir(parents=True, exist_ok=True)
    model = motion.model
    idx = np.arange(motion.n_frames) if frames is None else np.atleast_1d(np.arange(motion.n_frames)[frames])
    idx = idx[::stride].astype(np.int64)
    nodes, cells, topology = export_nodes(model, surface_only)
    jaw = tongue_offset(motion, "head")  # the jaw's translation (zeros when it did not move)
    offset = tongue_offset(motion, frame)
    note = f"{describe(frame, jaw_moves(motion))}; {_FIELD[frame]}"
    h5_name = h5_path.name
    n = len(nodes)

    def write(tmp_h5: Path, tmp_xdmf: Path) -> None:
        # HDF5 1.10's file format (ParaView 5.5+, any h5py of the last years): a dataset of one
        # chunk is indexed without a B-tree, 2.7 KB less per frame (7.5 KB instead of 10.1).
        with h5py.File(tmp_h5, "w", libver=("v110", "v110")) as h5, \
                open(tmp_xdmf, "w", encoding="utf-8") as xml:
            h5.attrs["format"] = "tonguevis motion (XDMF 3 time series)"
            from tonguevis.sim.placement import frame_words

            h5.attrs["units"] = f"metres, seconds; axes x anterior, y left, z up ({frame_words(motion)})"
            h5.attrs["frame_of_reference"] = note
            h5.attrs["warping"] = bool(motion.warping)
            h5.attrs["modes"] = int(motion.q.shape[1])
            h5.attrs["recording"] = str(motion.metadata.get("recording", {}).get("file", ""))
            h5.create_dataset("mesh/points", data=np.asarray(model.mesh.points[nodes], dtype=np.float64))
            h5.create_dataset("mesh/cells", data=cells.astype(np.int32))
            h5.create_dataset("mesh/node_ids", data=nodes.astype(np.int64))
            h5.create_dataset("times", data=np.asarray(motion.times, dtype=np.float64)[idx])
            h5.create_dataset("frames", data=idx)
            h5.create_dataset("jaw_offset", data=jaw[idx])
            xml.write(_header(h5_name, n, cells.shape, topology, note))
            groups: dict[str, object] = {"displacement": h5.create_group("displacement")}
            step = 0
            for sel, disp in motion.iter_displacements(chunk=chunk, frames=idx, nodes=nodes, dtype=np.float32):
                disp += offset[sel][:, None, :].astype(np.float32)
                fields = {"displacement": quantized(disp)}
                if extra_fields is not None:
                    fields.update({k: np.asarray(v, dtype=np.float32) for k, v in extra_fields(sel).items()})
                for k, i in enumerate(sel):
                    name = f"{step:06d}"
                    xml.write(f'      <Grid Name="step {step}" GridType="Uniform">\n'
                              '        <xi:include xpointer="xpointer(//Grid[@Name=&quot;mesh&quot;]/*[self::Topology '
                              'or self::Geometry])"/>\n'
                              f'        <Time Value="{motion.times[i]:.9g}"/>\n')
                    for field, values in fields.items():
                        if field not in groups:
                            groups[field] = h5.create_group(field)
                        _dataset(groups[field], name, values[k])
                        xml.write(_attribute(field, values[k].shape, f"{h5_name}:/{field}/{name}"))
                    xml.write("      </Grid>\n")
                    step += 1
                report(progress, step, len(idx), "writing the ParaView export")
            xml.write("    </Grid>\n  </Domain>\n</Xdmf>\n")

    # The HDF5 file is renamed into place first, then the XDMF that points to it: a reader never
    # finds an .xdmf whose .h5 is missing or half written.
    atomic_write(path, lambda tmp_xdmf: atomic_write(h5_path, lambda tmp_h5: write(tmp_h5, tmp_xdmf)))
    return path


def export_nodes(model, surface_only: bool) -> tuple[np.ndarray, np.ndarray, str]:
    """(nodes (n,), cells into them, XDMF topology): the surface triangles and their nodes, or every tet."""
    if surface_only:
        faces = np.asarray(model.surface_faces, dtype=np.int64)
        nodes = np.unique(faces)
        return nodes, np.searchsorted(nodes, faces), "Triangle"
    return np.arange(model.mesh.n_nodes), np.asarray(model.mesh.tets, dtype=np.int64), "Tetrahedron"


def quantized(displacement: np.ndarray) -> np.ndarray:
    """``displacement`` (float32, m) rounded to :data:`DISPLACEMENT_QUANTUM`, in place; returned."""
    scale = np.float32(1.0 / DISPLACEMENT_QUANTUM)
    np.multiply(displacement, scale, out=displacement)  # exact: a power of two
    np.round(displacement, out=displacement)
    np.divide(displacement, scale, out=displacement)
    return displacement


def _dataset(group, name: str, values: np.ndarray) -> None:
    """One small dataset, one chunk, shuffled and deflated, through h5py's low-level API
    (2x faster than ``create_dataset`` when a long recording makes hundreds of thousands)."""
    import h5py

    values = np.ascontiguousarray(values)
    properties = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    properties.set_chunk(values.shape)
    properties.set_shuffle()
    properties.set_deflate(DEFLATE_LEVEL)
    dataset = h5py.h5d.create(group.id, name.encode(), h5py.h5t.py_create(values.dtype),
                              h5py.h5s.create_simple(values.shape), properties)
    dataset.write(h5py.h5s.ALL, h5py.h5s.ALL, values)


def _header(h5_name: str, n: int, cell_shape: tuple[int, int], topology: str, note: str) -> str:
    from xml.sax.saxutils import quoteattr

    return (
        '<?xml version="1.0"?>\n'
        '<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
        "  <Domain>\n"
        f'    <Information Name="frame_of_reference" Value={quoteattr(note)}/>\n'
        '    <Information Name="units" Value="metres, seconds; x anterior, y left, z up"/>\n'
        '    <Grid Name="mesh" GridType="Uniform">\n'
        f'      <Geometry GeometryType="XYZ">\n'
        f'        <DataItem DataType="Float" Dimensions="{n} 3" Format="HDF" Precision="8">'
        f"{h5_name}:/mesh/points</DataItem>\n"
        "      </Geometry>\n"
        f'      <Topology TopologyType="{topology}" NumberOfElements="{cell_shape[0]}">\n'
        f'        <DataItem DataType="Int" Dimensions="{cell_shape[0]} {cell_shape[1]}" Format="HDF" '
        f'Precision="4">{h5_name}:/mesh/cells</DataItem>\n'
        "      </Topology>\n"
        "    </Grid>\n"
        '    <Grid Name="frames" GridType="Collection" CollectionType="Temporal">\n'
    )


def _attribute(name: str, shape: tuple, ref: str) -> str:
    kind = "Vector" if len(shape) == 2 and shape[1] == 3 else "Scalar"
    dims = " ".join(str(s) for s in shape)
    return (f'        <Attribute Name="{name}" AttributeType="{kind}" Center="Node">\n'
            f'          <DataItem DataType="Float" Dimensions="{dims}" Format="HDF" Precision="4">{ref}</DataItem>\n'
            "        </Attribute>\n")
