"""lumigraph: image-based capture and reconstruction.

One import namespace over the user's folders (``setuptools`` ``package-dir``
maps each name onto its folder):

- :mod:`lumigraph.capture` — the ground floor: errors, atomic artifacts and
  sidecars, image and artifact readers, the camera and rig model, and the
  synthetic scenes with exact ground truth;
- :mod:`lumigraph.calib` — calibration, stereo rigs, rectification;
- :mod:`lumigraph.stereo` — optical flow, video matching, stereo, SfM,
  model-based stereo;
- :mod:`lumigraph.hdr` — response recovery, radiance merge, tone mapping,
  HDR formats, HDR video;
- :mod:`lumigraph.lightfield` — light fields and refocusing;
- :mod:`lumigraph.separation` — direct/global separation;
- the shell on top: :mod:`lumigraph.command` (the ``lumigraph`` console
  script), :mod:`lumigraph.bench`, :mod:`lumigraph.inspect`.

The floor order and what may import what are drawn in ``ARCHITECTURE.md``.
Importing ``lumigraph`` imports none of the stages.

Examples
--------
>>> import lumigraph
>>> lumigraph.__version__
'0.1.0'
"""

__version__ = "0.1.0"
