"""Resampling on a torch device with OpenCV's pixel conventions (``cv2.remap``).

``remap(image, map_x, map_y)`` samples ``image`` at the pixel coordinates of
the maps, pixel centres at integers, as ``cv2.remap(..., INTER_LINEAR)`` does.
It goes through :func:`kornia.geometry.transform.remap`, which normalises pixel
coordinates as ``2 x / (W - 1) - 1`` (the ``align_corners=True`` convention)
whatever ``align_corners`` it is given: with the default (``False``) even an
identity map moves the image by a fraction of a pixel (kornia issue #4504).
We always pass ``align_corners=True``; the tests compare identity and
known-shift maps with ``cv2.remap`` on asymmetric images.

Borders: ``"constant"`` (zero outside, ``cv2.BORDER_CONSTANT`` with value 0:
grid_sample's ``zeros``), ``"replicate"`` (``BORDER_REPLICATE``: ``border``)
and ``"reflect101"`` (``BORDER_REFLECT_101``: ``reflection`` about the edge
pixel centres, which is what ``align_corners=True`` reflects about).

Precision: the normalisation and grid_sample's unnormalisation are two float32
roundings of a coordinate up to ``W - 1``, so the sample position is off by at
most ~``2 eps32 (W - 1)`` px (3e-5 px at 512) against cv2's exact one; cv2
itself rounds the fractional position to 1/32 px (``INTER_TAB_SIZE``). Maps
whose fractions are multiples of 1/32 are sampled alike by both.

torch and kornia are imported inside the functions (the ``gpu`` extra).
"""

from __future__ import annotations

BORDERS = {"constant": "zeros", "replicate": "border", "reflect101": "reflection"}


def remap(image, map_x, map_y, *, border: str = "constant"):
    """Bilinear sampling of ``image`` at ``(map_x, map_y)`` (pixel coordinates).

    Parameters
    ----------
    image : torch.Tensor, ``(B, C, H, W)`` float
    map_x, map_y : torch.Tensor, ``(B, H', W')`` or ``(H', W')`` float, px
        Source x (column) and y (row) of each output pixel; pixel centres at
        integers (cv2's convention). A 2-D map is shared by the batch.
    border : {"constant", "replicate", "reflect101"}

    Returns
    -------
    torch.Tensor, ``(B, C, H', W')``, the image's dtype.

    Examples
    --------
    >>> import torch
    >>> img = torch.arange(12.0).reshape(1, 1, 3, 4)
    >>> ys, xs = torch.meshgrid(torch.arange(3.0), torch.arange(4.0), indexing="ij")
    >>> remap(img, xs + 1, ys)[0, 0, 0].tolist()     # one pixel to the left, 0 outside
    [1.0, 2.0, 3.0, 0.0]
    """
    from kornia.geometry.transform import remap as kremap

    if border not in BORDERS:
        raise ValueError(f"border: expected one of {', '.join(BORDERS)}, got {border!r}")
    if map_x.ndim == 2:
        map_x, map_y = map_x[None], map_y[None]
    b = image.shape[0]
    if map_x.shape[0] != b:
        map_x, map_y = map_x.expand(b, -1, -1), map_y.expand(b, -1, -1)
    return kremap(image, map_x.to(image.dtype), map_y.to(image.dtype), mode="bilinear",
                  padding_mode=BORDERS[border], align_corners=True)


def remap_hwc(image, sampling_map, device, *, border: str = "constant"):
    """:func:`remap` for numpy ``(H, W[, C])`` float32 images and a cv2-style
    ``(H', W', 2)`` float32 map (x, y), on ``device`` (a
    :class:`lumigraph.capture.device.Device`); returns a torch tensor
    ``(H', W'[, C])`` on the device."""
    from lumigraph.capture.device import to_torch

    img = image if hasattr(image, "detach") else to_torch(image, device)
    m = sampling_map if hasattr(sampling_map, "detach") else to_torch(sampling_map, device)
    flat = img.ndim == 2
    x = img[..., None] if flat else img
    out = remap(x.permute(2, 0, 1)[None], m[..., 0], m[..., 1], border=border)[0].permute(1, 2, 0)
    return out[..., 0] if flat else out
