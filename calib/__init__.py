"""Camera calibration: target detection, intrinsics and distortion (Zhang),
stereo rigs, rectification and undistortion.

The camera and rig *model* (:class:`Camera`, ``camera.json``; :class:`Rig`,
``rig.json``) lives on the ground floor, in :mod:`lumigraph.capture.camera`
and :mod:`lumigraph.capture.rig`, because the synthetic scenes render
through it; it is re-exported here, loaded on first use.

Examples
--------
>>> from lumigraph.calib import Camera
>>> Camera.__module__
'lumigraph.capture.camera'
"""

from __future__ import annotations

from lumigraph.capture.lazy import attach

_LAZY = {
    "Camera": "lumigraph.capture.camera",
    "Rig": "lumigraph.capture.rig",
}
__getattr__, __dir__, __all__ = attach(__name__, _LAZY)
