"""Pictures of the core's results, without Qt: matplotlib figures and off-screen pyvista renders.

The analyses (:mod:`tonguevis.analysis`) compute with NumPy and SciPy only; what
draws them lives here, so a headless analysis never imports matplotlib or VTK.
The commands write files with these functions, and the app's tabs draw into
their own canvases and plotters with the same ones.  The app's 3D views are
:class:`.scene.TongueScene` in a Qt plotter; ``tonguevis export-video`` drives the
same scene off screen without loading Qt.

:mod:`.scene`         the four-view 3D scene (tongue, sensors, jaw, palate) and what it shows for a session, pyvista
:mod:`.drawing`       one frame's drawing data (frame of reference, palate, contact, midline), NumPy
:mod:`.frames`        per-frame points and colours of a motion made from q on demand, cached, NumPy
:mod:`.energy_density` elastic energy density per tet and node from strains, NumPy/SciPy
:mod:`.video`         the motion's MP4 (the four views, with its sound) and VTK series
:mod:`.mp4`           the one MP4 writer (imageio-ffmpeg), atomic
:mod:`.paraview`      the motion as one XDMF + HDF5 series with the energy density
:mod:`.label_tiers`   TextGrid tiers drawn under a waveform, matplotlib
:mod:`.segmentation_view` a segmentation's targets and partitions drawn on the tongue, NumPy
:mod:`.energy`        energy-time curves (Fig. 14) and MDS paths (Fig. 13), matplotlib
:mod:`.morph`         a morph's surface, cameras, PNG strips and MP4s (Figs. 15-16), pyvista
:mod:`.segmentation`  segmentation rows and grids (Figs. 17-18), pyvista
:mod:`.shading`       the app's lights evaluated at a surface's vertices (its 3D views draw unlit), NumPy
:mod:`.surface_geometry` closed or open, winding, outward vertex normals of a triangle surface, NumPy/SciPy

Importing this package costs nothing; its modules import their plotting library
inside the functions that need it (:mod:`.scene` imports pyvista when it is imported).
"""
