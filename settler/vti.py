"""VTK XML image data (``.vti``): a uniform grid's cell fields in the file ParaView opens as an image, with no
points or connectivity stored (a hexahedral ``.vtu`` of the same grid holds eight corner indices and the corner
points per cell besides). Written and read here by hand, to the VTK file-format specification ("VTK XML formats",
vtk.org): ``ImageData`` with ``WholeExtent`` over the grid's points, ``Origin`` and ``Spacing``, every array in
``CellData`` as float32, format ``binary`` (base64) compressed by zlib in one block with a UInt64 header. The
cell order is VTK's: x fastest, then y, then z. Shared by the full engine (writer) and analysis (reader), so it
imports NumPy only.
"""

from __future__ import annotations

import base64
import struct
import xml.etree.ElementTree as ET
import zlib

import numpy as np


def _encode(values: np.ndarray) -> str:
    raw = np.ascontiguousarray(values, dtype="<f4").tobytes()
    packed = zlib.compress(raw, 6)
    header = struct.pack("<4Q", 1, len(raw), len(raw), len(packed))
    return base64.b64encode(header).decode("ascii") + base64.b64encode(packed).decode("ascii")


def _decode(text: str, compressed: bool) -> bytes:
    text = "".join(text.split())
    if not compressed:
        data = base64.b64decode(text)
        (size,) = struct.unpack("<Q", data[:8])
        return data[8:8 + size]
    head = base64.b64decode(text[:44])  # 4 UInt64 = 32 bytes -> 44 base64 characters: one block
    blocks, _, _, = struct.unpack("<3Q", head[:24])
    header_chars = 4 * ((8 * (3 + blocks) + 2) // 3)
    head = base64.b64decode(text[:header_chars])
    sizes = struct.unpack(f"<{3 + blocks}Q", head)[3:]
    data = base64.b64decode(text[header_chars:])
    out, at = [], 0
    for size in sizes:
        out.append(zlib.decompress(data[at:at + size]))
        at += size
    return b"".join(out)


def image_bytes(shape, origin, spacing, cell_fields: dict[str, np.ndarray]) -> bytes:
    """The ``.vti`` file of a grid of ``shape`` (nx, ny, nz) cells of ``spacing`` [m] from ``origin`` [m], with the
    cell fields ``name -> array of shape (nx, ny, nz)`` or ``(nx, ny, nz, c)`` (our C order, x slowest; written in
    VTK's order)."""
    nx, ny, nz = (int(n) for n in shape)
    arrays = []
    for name, values in cell_fields.items():
        values = np.asarray(values)
        components = 1 if values.ndim == 3 else values.shape[3]
        if values.shape[:3] != (nx, ny, nz):
            raise ValueError(f"cell field {name}: shape {values.shape}, allowed: ({nx}, {ny}, {nz}[, c])")
        ordered = values.transpose(2, 1, 0, *range(3, values.ndim))  # z slowest, x fastest
        arrays.append(f'        <DataArray type="Float32" Name="{name}" NumberOfComponents="{components}" '
                      f'format="binary">{_encode(ordered)}</DataArray>')
    extent = f"0 {nx} 0 {ny} 0 {nz}"
    text = ('<?xml version="1.0"?>\n'
            '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
            'compressor="vtkZLibDataCompressor">\n'
            f'  <ImageData WholeExtent="{extent}" Origin="{" ".join(f"{o:.17g}" for o in origin)}" '
            f'Spacing="{spacing:.17g} {spacing:.17g} {spacing:.17g}">\n'
            f'    <Piece Extent="{extent}">\n      <CellData>\n' + "\n".join(arrays) +
            '\n      </CellData>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    return text.encode("ascii")


def read_image(path) -> tuple[tuple[int, int, int], np.ndarray, float, dict[str, np.ndarray]]:
    """(shape (nx, ny, nz), origin (3,) [m], spacing [m], cell fields name -> array (nx, ny, nz[, c]) float64) of a
    ``.vti`` file written by :func:`image_bytes` (uniform spacing, cell data, binary, zlib or raw). Raises
    ValueError naming the file for anything else."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ValueError(f"{path}: not a readable VTK XML file ({exc})") from None
    image = root.find("ImageData")
    if root.get("type") != "ImageData" or image is None or root.get("header_type", "UInt32") != "UInt64":
        raise ValueError(f"{path}: not VTK image data with UInt64 headers")
    extent = [int(v) for v in image.get("WholeExtent", "").split()]
    spacing = [float(v) for v in image.get("Spacing", "").split()]
    if len(extent) != 6 or len(spacing) != 3 or len(set(spacing)) != 1:
        raise ValueError(f"{path}: WholeExtent or uniform Spacing missing")
    shape = (extent[1] - extent[0], extent[3] - extent[2], extent[5] - extent[4])
    origin = np.array([float(v) for v in image.get("Origin", "0 0 0").split()])
    compressed = root.get("compressor") is not None
    fields = {}
    for array in image.iter("DataArray"):
        components = int(array.get("NumberOfComponents", "1"))
        values = np.frombuffer(_decode(array.text or "", compressed), dtype="<f4").astype(float)
        ordered = values.reshape(shape[2], shape[1], shape[0], components)
        fields[array.get("Name")] = ordered.transpose(2, 1, 0, 3)[..., 0] if components == 1 \
            else ordered.transpose(2, 1, 0, 3)
    return shape, origin, spacing[0], fields
