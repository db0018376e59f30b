"""Pictures of the core's results, without Qt: matplotlib figures and off-screen pyvista renders.

The analyses (:mod:`tonguevis.analysis`) compute with NumPy and SciPy only; what
draws them lives here, so a headless analysis never imports matplotlib or VTK.
The commands write files with these functions, and the app's tabs draw into
their own canvases and plotters with the same ones.

:mod:`.energy`        energy-time curves (Fig. 14) and MDS paths (Fig. 13), matplotlib
:mod:`.morph`         a morph's surface, cameras, PNG strips and MP4s (Figs. 15-16), pyvista
:mod:`.segmentation`  segmentation rows and grids (Figs. 17-18), pyvista
:mod:`.shading`       the app's lights evaluated at a surface's vertices (its 3D views draw unlit), NumPy
:mod:`.surface_geometry` closed or open, winding, outward vertex normals of a triangle surface, NumPy/SciPy

Every plotting library is imported inside the functions that need it: importing
this package costs nothing.
"""
