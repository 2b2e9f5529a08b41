"""Writes the .vti fixtures of crates/grid/tests/it/vti.rs with VTK's own writer (pip install vtk).

A 5 x 4 x 3 image, origin (1, 2, 3), spacing (0.5, 0.25, 2), whose point value at
index (i, j, k) is i + 10 j + 100 k, in every encoding vtkXMLImageDataWriter has; and a
cell-data image of the same extent whose cell value is i + 10 j + 100 k too.
"""
import vtk
from vtk.util import numpy_support
import numpy as np

def image(cell=False, dtype=np.int16):
    img = vtk.vtkImageData()
    img.SetDimensions(5, 4, 3)
    img.SetOrigin(1.0, 2.0, 3.0)
    img.SetSpacing(0.5, 0.25, 2.0)
    n = (4, 3, 2) if cell else (5, 4, 3)
    k, j, i = np.meshgrid(range(n[2]), range(n[1]), range(n[0]), indexing="ij")
    values = (i + 10 * j + 100 * k).astype(dtype).ravel()
    array = numpy_support.numpy_to_vtk(values, deep=True)
    array.SetName("density")
    (img.GetCellData() if cell else img.GetPointData()).SetScalars(array)
    return img

def write(name, img, mode, compress, header64=True, base64_appended=False):
    w = vtk.vtkXMLImageDataWriter()
    w.SetFileName(name)
    w.SetInputData(img)
    {"ascii": w.SetDataModeToAscii, "binary": w.SetDataModeToBinary,
     "appended": w.SetDataModeToAppended}[mode]()
    if compress:
        w.SetCompressorTypeToZLib()
        w.SetBlockSize(64)  # several blocks even for this small image
    else:
        w.SetCompressorTypeToNone()
    w.SetHeaderTypeToUInt64() if header64 else w.SetHeaderTypeToUInt32()
    if base64_appended:
        w.EncodeAppendedDataOn()
    else:
        w.EncodeAppendedDataOff()
    assert w.Write() == 1

write("ascii.vti", image(), "ascii", False)
write("binary.vti", image(), "binary", False)
write("binary_zlib.vti", image(), "binary", True)
write("appended_raw.vti", image(), "appended", False, header64=False)
write("appended_raw_zlib.vti", image(), "appended", True)
write("appended_base64_zlib.vti", image(), "appended", True, base64_appended=True)
write("cell_data_float.vti", image(cell=True, dtype=np.float32), "appended", False)
