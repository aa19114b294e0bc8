"""XDMF 3 sidecar for a run file, so that ParaView (and VisIt) open the particle time series.

The XDMF file holds light metadata only: every array is a reference into the HDF5 run file
(frame ``i`` of ``/frames/<field>`` through a HyperSlab, so nothing is copied).  The HDF5 path in
the XDMF is relative (the file name when both lie in the same folder), so the pair can be moved
together.

This module imports numpy, h5py and the standard library only.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np

from .hdf5 import RunFile

__all__ = ["write_xdmf", "xdmf_path_for"]

_HEADER = '<?xml version="1.0" ?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n'


def xdmf_path_for(h5_path: str | Path) -> Path:
    """``<run>.xdmf`` beside ``<run>.h5``."""
    return Path(h5_path).with_suffix(".xdmf")


def _number_type(dtype: np.dtype) -> tuple[str, int]:
    dt = np.dtype(dtype)
    size = dt.itemsize
    if dt.kind == "f":
        return "Float", size
    if dt.kind == "b":
        return "UChar", 1
    if dt.kind == "i":
        return ("Char", 1) if size == 1 else ("Short", 2) if size == 2 else ("Int", size)
    if dt.kind == "u":
        return ("UChar", 1) if size == 1 else ("UShort", 2) if size == 2 else ("UInt", size)
    raise ValueError(f"no XDMF number type for dtype {dt}")


def _dims(shape) -> str:
    return " ".join(str(int(s)) for s in shape)


def _hdf_item(parent: ET.Element, ds: h5py.Dataset, ref: str) -> ET.Element:
    ntype, prec = _number_type(ds.dtype)
    item = ET.SubElement(
        parent,
        "DataItem",
        Dimensions=_dims(ds.shape),
        NumberType=ntype,
        Precision=str(prec),
        Format="HDF",
    )
    item.text = f"{ref}:{ds.name}"
    return item


def _frame_slab(parent: ET.Element, ds: h5py.Dataset, ref: str, i: int, result_shape) -> ET.Element:
    """HyperSlab selecting frame ``i`` of a (F, N, ...) dataset."""
    rank = len(ds.shape)
    slab = ET.SubElement(parent, "DataItem", ItemType="HyperSlab", Dimensions=_dims(result_shape),
                         Type="HyperSlab")
    sel = ET.SubElement(slab, "DataItem", Dimensions=f"3 {rank}", Format="XML", NumberType="Int")
    start = [i] + [0] * (rank - 1)
    stride = [1] * rank
    count = [1, *ds.shape[1:]]
    sel.text = " ".join(map(str, start + stride + count))
    _hdf_item(slab, ds, ref)
    return slab


def _attribute_layout(trailing: tuple[int, ...], dim: int) -> tuple[str, tuple[int, ...]] | None:
    """XDMF AttributeType and per-particle component shape for a field's per-particle shape."""
    if trailing == ():
        return "Scalar", ()
    if len(trailing) == 1:
        k = trailing[0]
        if k == dim:
            return "Vector", (k,)
        if k == 6 and dim == 3:
            return "Tensor6", (6,)
        if k == 9:
            return "Tensor", (9,)
        return "Matrix", (k,)
    if len(trailing) == 2:
        k = int(trailing[0] * trailing[1])
        return ("Tensor" if k == 9 else "Matrix"), (k,)
    return None  # rank > 2 per particle: no XDMF representation


def write_xdmf(h5_path: str | Path, xdmf_path: str | Path | None = None, *, markers: bool = False) -> Path:
    """Write the XDMF sidecar of run file ``h5_path``; returns its path.

    Default location: ``<run>.xdmf`` beside the HDF5 file.  One Uniform Grid per frame in a
    temporal collection: Polyvertex topology over all N particles, geometry ``XYZ`` (3D) or
    ``XY`` (2D) from ``/frames/position``, one node Attribute per frame field (booleans read as
    unsigned chars 0 / 1) plus ``kind`` and ``id`` from ``/particles``.  With ``markers=True`` and soil markers
    in the file, a second (static) grid ``markers`` carries porosity and d50.
    """
    h5_path = Path(h5_path)
    out = Path(xdmf_path) if xdmf_path is not None else xdmf_path_for(h5_path)
    ref = os.path.relpath(h5_path.resolve(), out.resolve().parent).replace(os.sep, "/")

    with RunFile(h5_path) as run:
        f = run.h5
        dim = run.dim
        n = run.n_particles
        n_frames = run.n_frames
        times = run.times
        fields = run.field_names
        if n_frames and "position" not in fields:
            raise ValueError(f"{h5_path}: frames have no 'position' field; cannot write XDMF")
        frames = f["frames"] if "frames" in f else None

        root = ET.Element("Xdmf", {"Version": "3.0", "xmlns:xi": "http://www.w3.org/2001/XInclude"})
        domain = ET.SubElement(root, "Domain")
        series = ET.SubElement(domain, "Grid", Name="particles", GridType="Collection",
                               CollectionType="Temporal")

        layouts = {}
        for name in fields:
            lay = _attribute_layout(tuple(frames[name].shape[2:]), dim)
            if lay is not None and name != "position":
                layouts[name] = lay

        for i in range(n_frames):
            grid = ET.SubElement(series, "Grid", Name=f"frame_{i:05d}", GridType="Uniform")
            ET.SubElement(grid, "Time", Value=repr(float(times[i])))
            ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(n),
                          NodesPerElement="1")
            geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY")
            _frame_slab(geom, frames["position"], ref, i, (n, dim))
            for name, (atype, comp) in layouts.items():
                attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=atype, Center="Node")
                _frame_slab(attr, frames[name], ref, i, (n, *comp))
            for name in ("kind", "id"):
                ds = f["particles"][name]
                attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType="Scalar", Center="Node")
                _hdf_item(attr, ds, ref)

        if markers and "markers" in f and "position" in f["markers"]:
            mg = f["markers"]
            m = int(mg["position"].shape[0])
            grid = ET.SubElement(domain, "Grid", Name="markers", GridType="Uniform")
            ET.SubElement(grid, "Topology", TopologyType="Polyvertex", NumberOfElements=str(m),
                          NodesPerElement="1")
            geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ" if dim == 3 else "XY")
            _hdf_item(geom, mg["position"], ref)
            for name in mg.keys():
                ds = mg[name]
                if name == "position" or not isinstance(ds, h5py.Dataset):
                    continue
                lay = _attribute_layout(tuple(ds.shape[1:]), dim)
                if lay is None or lay[0] not in ("Scalar", "Vector"):
                    continue
                attr = ET.SubElement(grid, "Attribute", Name=name, AttributeType=lay[0], Center="Node")
                _hdf_item(attr, ds, ref)

    ET.indent(root, space="  ")
    text = _HEADER + ET.tostring(root, encoding="unicode") + "\n"
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)
    return out
