"""The neighbour warp of HDR video (Kang et al. 2003) on a torch device.

S. B. Kang, M. Uyttendaele, S. Winder and R. Szeliski, "High Dynamic Range
Video", SIGGRAPH 2003, doi:10.1145/882262.882270. :func:`hdr.kang2003.hdr_video`
completes each frame from its neighbours pulled onto it along the flow;
the pull (:func:`hdr.kang2003._warp_neighbour`: normalised bilinear
interpolation of radiance and variance over the neighbour's reliable pixels)
is three ``cv2.remap`` calls per neighbour. Here they are
:func:`lumigraph.capture.warp_torch.remap` on the device, with cv2's pixel
convention and constant (zero) border. The flow, the tests and the merge of
the accepted neighbours stay on the CPU.

Not bit-for-bit: ``cv2.remap`` rounds each sample position to 1/32 px
(``INTER_TAB_SIZE``), grid_sample does not; a sample moves by at most 1/64 px
in x and in y, so a warped value differs by at most 1/64 of the largest
difference between horizontally or vertically adjacent source values, per
axis, plus float32 rounding (``tests/device/test_hdr_torch.py``). The
acceptance tests downstream threshold those values, so a pixel at a threshold
may be accepted on one device and not the other.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.device import resolve_device
>>> from lumigraph.hdr.kang2003 import _grid, _Linear, _warp_neighbour
>>> rng = np.random.default_rng(0)
>>> x = rng.random((2, 6, 7, 3)).astype(np.float32)
>>> video = _Linear(x=list(x), reliable=list(x > 0.1), var=list(x * 0.01))
>>> m = _grid(6, 7) + np.float32(0.25)
>>> a = warp_neighbour_torch(video, 1, m, resolve_device("torch-cpu"))
>>> b = _warp_neighbour(video, 1, m)
>>> bool(np.abs(a.x - b.x).max() < 1e-5), bool((a.reliable == b.reliable).all())
(True, True)
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import to_numpy, to_torch


def warp_neighbour_torch(video, j, sampling_map, device):
    """:func:`hdr.kang2003._warp_neighbour` on ``device`` (a resolved
    :class:`lumigraph.capture.device.Device`); returns the same ``_Warped``
    (numpy, on the host)."""
    import torch

    from lumigraph.capture.warp_torch import remap_hwc
    from lumigraph.hdr.kang2003 import _Warped

    m = to_torch(sampling_map, device)
    rel = to_torch(video.reliable[j], device, dtype=torch.bool)
    rw = remap_hwc(rel.to(torch.float32), m, device)
    rws = torch.clamp(rw, min=np.float32(1e-6))
    x = remap_hwc(torch.where(rel, to_torch(video.x[j], device), 0.0), m, device) / rws
    var = remap_hwc(torch.where(rel, to_torch(video.var[j], device), 0.0), m, device) / rws
    return _Warped(x=to_numpy(x), var=to_numpy(var), reliable=to_numpy(rw > 0.5))
