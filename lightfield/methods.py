"""The light-field stage's method registries: the CLI's ``--method`` names
and the functions they call.

Every refocusing method takes ``(lf, slopes, **options)`` and returns the
photographs refocused at ``slopes`` as one ``(N, H, W, C)`` float32 array on
the centre view's grid, so a method that pays a one-time cost (the 4-D FFT of
Fourier slice refocusing) pays it once per stack.

Examples
--------
>>> REFOCUS_METHODS.names
('shift-add', 'fourier')
>>> REFOCUS_METHODS["shift-add"].options
('kernel',)
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

REFOCUS_METHODS = Registry("refocus", [
    Method("shift-add", "lumigraph.lightfield.refocus:shift_and_add_stack",
           "shift-and-add of the views (Ng 2005 eq. 5.9): one pass over the views per value",
           options=("kernel",)),
    Method("fourier", "lumigraph.lightfield.ng2005:refocus_stack",
           "Fourier slice photography (Ng 2005 eqs. 5.10-5.11): one 4-D FFT, then a 2-D "
           "slice per value",
           options=("max_slope", "oversample", "kernel_width", "interpolation")),
])
