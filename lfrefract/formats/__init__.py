"""File formats: what lfrefract reads and writes, and how it writes without losing data.

- :mod:`~lfrefract.formats.exr`: float OpenEXR images tagged with their role.
- :mod:`~lfrefract.formats.jsonio`: JSON sidecars with a schema version.
- :mod:`~lfrefract.formats.flatport`: a flat port as one line of text (Refractive COLMAP layout).
- :mod:`~lfrefract.formats.paramfile`: camera and port files (TOML, JSON, or the flat-port text).
- :mod:`~lfrefract.formats.ply`: point clouds.
- :mod:`~lfrefract.formats.viewstack`: sub-aperture view stacks (HCI benchmark layout).
- :mod:`~lfrefract.formats.pfm`: Portable Float Map images (the HCI benchmark's disparity maps).
- :mod:`~lfrefract.formats.capture`: a capture (raw image, camera, port, ground truth) as a folder,
  or a Lytro file.
- :mod:`~lfrefract.formats.mosaic`: a sensor's Bayer mosaic of integer counts, demosaicing, ``mosaic.npz``.
- :mod:`~lfrefract.formats.lytro`: Lytro's LFR and raw files.
- :mod:`~lfrefract.formats.whites`: white images of Lytro captures: finding, choosing, developing.
- :mod:`~lfrefract.formats.outputs`: atomic files, staged output folders and ``--overwrite``.

Import from the modules themselves; this package imports none of them, so that low layers can
use :mod:`~lfrefract.formats.exr` without pulling in the capture reader.
"""
