"""The camera response curve: the result every response method returns.

A :class:`ResponseCurve` holds, per colour channel, the table
``g[c, z] = ln f⁻¹(z)`` for every code value ``z`` of the stack's bit depth
(reference ch. 6, eq. 6.3: ``g(Z) = ln E + ln Δt``). Each channel's table is
defined up to an additive constant; every method here fixes it the same way
(:func:`normalise_g`: ``f⁻¹(z_max) = 1`` at the top code, the exposure that
fills a well, the same for every channel; a linear sensor's curve is then
``z / z_max`` whatever its bit depth), which keeps merged radiance in the
same units for 8-, 12- and 16-bit input and in the same colour balance as
the sensor's.

``response.json`` (DESIGN §4) stores ``method``, ``bit_depth``, ``g`` (one
list of ``2**bit_depth`` values per channel), ``exposure_times`` (as used or
refined), ``selection`` (λ or order, every candidate's score and the choice),
``warnings`` and ``fit`` (method-specific diagnostics such as polynomial
coefficients and residuals).

Examples
--------
>>> import numpy as np
>>> r = ResponseCurve.linear(8)
>>> r.g.shape, r.linearize(np.array([[255, 51, 0]], np.uint8)).tolist()
((3, 256), [[1.0, 0.20000000298023224, 0.0]])
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

SCHEMA = "lumigraph.response"
SCHEMA_VERSION = 1


def normalise_g(g: np.ndarray) -> np.ndarray:
    """Fix each channel's free additive constant: ``f⁻¹(z_max) = 1``.

    A bracket fixes each channel's curve only up to a scale of exposure, so
    the balance between channels must come from an assumption. The one a
    sensor makes true is that every channel's well fills at the same
    exposure: the top code means the same ``X`` in red, green and blue.
    (Pinning the middle code instead, as OpenCV does, is the right balance
    only when the three curves are identical; with per-channel curves it
    tints the merged radiance: 15 % relative error on the bench's
    ``outdoor`` kind against 1 % with the top code pinned.)

    Parameters
    ----------
    g : ndarray, ``(C, 2**bit_depth)`` float
        ``ln f⁻¹(z)`` per channel, each up to an additive constant.

    Returns
    -------
    ndarray, ``(C, 2**bit_depth)`` float64
        A new array; ``exp(g)`` is then relative exposure with the top code
        mapping to 1, so an ideal linear sensor gives ``z / z_max``.

    Examples
    --------
    >>> g = np.log(np.arange(256) + 1.0)[None] + 3.0
    >>> round(float(np.exp(normalise_g(g))[0, 255]), 6), round(float(np.exp(normalise_g(g))[0, 127]), 6)
    (1.0, 0.5)
    """
    g = np.asarray(g, dtype=np.float64)
    return g - g[..., -1:]


@dataclass(frozen=True)
class ResponseCurve:
    """An inverse camera response ``g(z) = ln f⁻¹(z)`` per channel.

    Attributes
    ----------
    method : str
        ``"debevec"``, ``"mitsunaga-nayar"``, ``"robertson"``, ``"linear"``, …
    bit_depth : int
        True bit depth of the codes (1..16).
    g : ndarray, ``(C, 2**bit_depth)`` float64
        ``ln f⁻¹(z)`` per channel (natural log of relative exposure ``E·Δt``),
        each channel defined up to an additive constant. Read-only.
    exposure_times_s : tuple of float or None
        Exposure times the fit used, or refined ones (Mitsunaga–Nayar).
    selection : dict
        Model selection: the chosen λ or polynomial order, every candidate's
        score and how the choice was made.
    warnings : tuple of str
        What the user should know (few samples, clipped channels, …).
    fit : dict
        Method-specific diagnostics (coefficients, residual RMS, …).
    """

    method: str
    bit_depth: int
    g: np.ndarray
    exposure_times_s: tuple[float, ...] | None = None
    selection: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    fit: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.method, str) or not self.method:
            raise TypeError(f"method: expected a non-empty str, got {self.method!r}")
        if not isinstance(self.bit_depth, int | np.integer) or not 1 <= int(self.bit_depth) <= 16:
            raise ValueError(f"bit_depth: expected an integer in 1..16, got {self.bit_depth!r}")
        g = np.array(self.g, dtype=np.float64)
        if g.ndim == 1:
            g = g[None]
        n = 2 ** int(self.bit_depth)
        if g.ndim != 2 or g.shape[1] != n or g.shape[0] < 1:
            raise ValueError(f"g: expected (C, {n}) for bit depth {self.bit_depth}, got "
                             f"{np.shape(self.g)}")
        if not np.isfinite(g).all():
            raise ValueError("g: expected finite values of ln f^-1(z), got NaN/inf")
        g.setflags(write=False)
        object.__setattr__(self, "g", g)
        object.__setattr__(self, "bit_depth", int(self.bit_depth))
        if self.exposure_times_s is not None:
            t = tuple(float(x) for x in self.exposure_times_s)
            if not all(math.isfinite(x) and x > 0 for x in t):
                raise ValueError(f"exposure_times_s: expected positive finite times, got {t}")
            object.__setattr__(self, "exposure_times_s", t)
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))
        object.__setattr__(self, "selection", dict(self.selection))
        object.__setattr__(self, "fit", dict(self.fit))

    @property
    def channels(self) -> int:
        """Number of colour channels ``C``."""
        return int(self.g.shape[0])

    @property
    def code_max(self) -> int:
        """The largest code value, ``2**bit_depth - 1``."""
        return 2 ** self.bit_depth - 1

    def exposure_table(self) -> np.ndarray:
        """``f⁻¹(z)`` per channel, ``(C, 2**bit_depth)`` float64 (``exp(g)``; exactly
        ``z / z_max`` for the linear response, so code 0 maps to 0)."""
        if self.method == "linear":
            return np.broadcast_to(np.arange(self.code_max + 1) / self.code_max,
                                   self.g.shape).copy()
        return np.exp(self.g)

    def linearize(self, codes: np.ndarray) -> np.ndarray:
        """Map integer code values to relative exposure ``E·Δt = f⁻¹(z)``.

        Parameters
        ----------
        codes : ndarray of int, ``(..., C)``
            Code values in ``[0, 2**bit_depth)``; the last axis is the channel
            (length ``C``; a one-channel curve applies to every channel).

        Returns
        -------
        ndarray, float32, same shape
            Relative exposure, linear (``exp(g[c, z])``).

        Raises
        ------
        TypeError
            Float codes.
        ValueError
            Channel count mismatch or codes outside the bit depth.
        """
        codes = np.asarray(codes)
        if codes.dtype.kind not in "ui":
            raise TypeError(f"codes: expected integer code values, got {codes.dtype}")
        if codes.ndim == 0:
            raise ValueError("codes: expected an array (..., C), got a scalar")
        c = codes.shape[-1]
        if self.channels not in (1, c):
            raise ValueError(f"codes: expected {self.channels} channels (last axis), got {c}")
        if codes.size and (int(codes.min()) < 0 or int(codes.max()) > self.code_max):
            raise ValueError(f"codes: expected values in 0..{self.code_max} "
                             f"(bit depth {self.bit_depth}), got {int(codes.min())}.."
                             f"{int(codes.max())}")
        table = self.exposure_table().astype(np.float32)
        if self.channels == 1:
            return table[0][codes]
        out = np.empty(codes.shape, np.float32)
        for ch in range(c):
            out[..., ch] = table[ch][codes[..., ch]]
        return out

    # -------------------------------------------------------------- artifact
    def to_dict(self) -> dict:
        """The ``response.json`` body (JSON-able)."""
        return {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "method": self.method,
                "bit_depth": self.bit_depth, "channels": self.channels,
                "g": [row.tolist() for row in self.g],
                "exposure_times": None if self.exposure_times_s is None
                else list(self.exposure_times_s),
                "selection": self.selection, "warnings": list(self.warnings), "fit": self.fit}

    @classmethod
    def from_dict(cls, d: dict, *, where: str | os.PathLike = "response") -> ResponseCurve:
        """Build from a ``response.json`` body; :class:`InputError` naming
        ``where`` (the file) and the key at fault: ``method`` not a name,
        ``bit_depth`` not an integer in 1..16, ``g`` not ``C`` rows of
        ``2**bit_depth`` finite numbers (``channels`` when given), the
        exposure times not positive numbers, ``selection``/``fit`` not
        objects, ``warnings`` not strings.

        >>> body = ResponseCurve.linear(2, channels=1).to_dict()
        >>> body["g"][0][3] = "dark"
        >>> ResponseCurve.from_dict(body, where="response.json")
        Traceback (most recent call last):
        ...
        lumigraph.capture.errors.InputError: response.json: key 'g[0][3]': expected a number, got 'dark'
        """
        from lumigraph.capture.schema import fail, require, require_object

        require_object(d, path=where, where="", keys=("method", "bit_depth", "g"),
                       what="a response curve (method, bit_depth, g)")
        method = require(d, "method", "string", path=where)
        bit_depth = require(d, "bit_depth", "integer", low=1, high=16, path=where)
        n = 2 ** bit_depth
        g = d["g"]
        if isinstance(g, list) and g and not isinstance(g[0], list):  # one channel, flat
            g = [g]
        g = require({"g": g}, "g", "matrix", shape=(None, n), path=where)
        channels = require(d, "channels", "integer", low=1, default=len(g), path=where)
        if channels != len(g):
            raise fail(where, "channels", f"{channels} channels, but g has {len(g)} rows")
        times = require(d, "exposure_times", "list", items="number", above=0, min_length=1,
                        nullable=True, default=None, path=where)
        selection = require(d, "selection", "object", nullable=True, default=None, path=where)
        warnings = require(d, "warnings", "list", items="string", nullable=True, default=None,
                           path=where)
        fit = require(d, "fit", "object", nullable=True, default=None, path=where)
        try:
            return cls(method, bit_depth, g, times, selection or {}, tuple(warnings or ()),
                       fit or {})
        except (TypeError, ValueError) as e:  # the checks above should leave none
            raise InputError(where, f"invalid response curve ({e})") from None

    def save(self, path: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write ``response.json`` and its ``.meta.json`` sidecar atomically.

        ``meta`` is a sidecar from :func:`capture.artifact.make_meta`; a minimal
        one is made when omitted.
        """
        from lumigraph.capture.artifact import make_meta, save_json_artifact

        if meta is None:
            meta = make_meta(SCHEMA, model={"method": self.method, "selection": self.selection},
                             warnings=self.warnings)
        return save_json_artifact(path, self.to_dict(), meta=meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> ResponseCurve:
        """Read a ``response.json``; InputError naming the file if it is not one."""
        from lumigraph.capture.artifact import load_json_artifact

        if not Path(path).exists():
            raise InputError(path, "response file not found (make one with 'lumigraph hdr response')")
        return cls.from_dict(load_json_artifact(path, "response curve", schemas=(SCHEMA,),
                                                versions=(SCHEMA_VERSION,)), where=str(path))

    @classmethod
    def linear(cls, bit_depth: int, channels: int = 3, *, reason: str = "") -> ResponseCurve:
        """The identity response of RAW/linear data: ``f⁻¹(z) = z / z_max``.

        ``g[0]`` (``ln 0``) is stored as the log of half a code so the table
        stays finite; :meth:`linearize` still maps code 0 to exactly 0.
        """
        if not isinstance(bit_depth, int | np.integer) or not 1 <= int(bit_depth) <= 16:
            raise ValueError(f"bit_depth: expected an integer in 1..16, got {bit_depth!r}")
        if not isinstance(channels, int | np.integer) or channels < 1:
            raise ValueError(f"channels: expected a positive integer, got {channels!r}")
        zmax = 2 ** int(bit_depth) - 1
        z = np.arange(zmax + 1, dtype=np.float64)
        z[0] = 0.5
        g = np.tile(np.log(z / zmax), (int(channels), 1))
        sel = {"model": "linear", "reason": reason or "linear data: no response curve needed"}
        return cls("linear", int(bit_depth), g, None, sel, ())
