"""Projector patterns for direct/global separation (Nayar et al. 2006, reference §8.3).

Every pattern is a float32 array ``(H, W)`` at projector resolution with values
in ``[0, 1]`` (1 = pixel on). The projector's black level ``b`` is a property of
the projector, not of the pattern: the light it emits is ``b + (1 - b)·pattern``
(see :func:`emitted`).

A :class:`PatternSet` keeps the order the separation expects and what each
image is:

=============  ==================================================================
kind           images, in order
=============  ==================================================================
``checker``    the ``shifts²`` shifted checkerboards, then their complements in the
               same order (image ``i + m`` is the complement of image ``i``)
``block``      lit fraction α ≠ 0.5: the ``n²`` cyclic shifts of a compact block
               of ``round(α n²)`` lit cells in each ``n×n``-cell tile
``sinusoid``   three phase-shifted sinusoids ``0.5 + 0.5 cos(2πx/period + 2πk/3)``
``stripe``     one image of vertical stripes (single-image method)
``occluder``   a comb of thin dark bars sweeping one step per image (shadow sweep)
``flat``       all-black then all-white frames (for estimating ``b``)
=============  ==================================================================

Patterns are periodic with a period of ``2·square`` projector pixels (checker),
``period`` (sinusoid, stripe, occluder); :func:`cell_weights` reads a pattern
back as one weight per residue class of a cell lattice, which is how the
synthetic projector scene composes any pattern from a few basis renders.

Examples
--------
>>> ps = checker_set((16, 8), square=4, shifts=2)
>>> len(ps), ps.kind, ps.images.shape, ps.complement_of[4]
(8, 'checker', (8, 8, 16), 0)
>>> bool(np.all(ps.images[0] + ps.images[4] == 1.0))
True
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

KINDS = ("checker", "block", "sinusoid", "stripe", "occluder", "flat")


def check_lit_fraction(alpha: float) -> float:
    """A lit fraction ``alpha`` (of a pattern, or of the patterns a separation
    assumes): strictly between 0 and 1.

    Raises
    ------
    InputError
        Naming ``alpha``.

    Examples
    --------
    >>> check_lit_fraction(0.25)
    0.25
    >>> try:
    ...     check_lit_fraction(1.0)
    ... except InputError as e:
    ...     print(e)
    alpha: lit fraction must lie in (0, 1), got 1.0
    """
    if not 0.0 < alpha < 1.0:
        raise InputError("alpha", f"lit fraction must lie in (0, 1), got {alpha}")
    return alpha


@dataclass(frozen=True)
class PatternSet:
    """An ordered set of projector patterns.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    images : ndarray, ``(N, H, W)`` float32 in [0, 1]
        The patterns at projector resolution.
    names : tuple of str
        File stem per image (``checker_00`` …).
    lit_fraction : tuple of float
        Fraction α of projector pixels on in each image (mean of the pattern).
    complement_of : tuple of int
        Index of each image's complement in the set, ``-1`` when it has none.
    info : dict
        Generation parameters (square, shifts, period, …), JSON-able.
    """

    kind: str
    images: np.ndarray
    names: tuple[str, ...]
    lit_fraction: tuple[float, ...]
    complement_of: tuple[int, ...]
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind: expected one of {KINDS}, got {self.kind!r}")
        if self.images.ndim != 3:
            raise ValueError(f"images: expected (N, H, W), got {self.images.shape}")
        n = len(self.images)
        if not (len(self.names) == len(self.lit_fraction) == len(self.complement_of) == n):
            raise ValueError("names, lit_fraction, complement_of: one entry per image expected")
        if self.images.size and (self.images.min() < 0 or self.images.max() > 1):
            raise ValueError("images: pattern values must lie in [0, 1]")

    def __len__(self) -> int:
        return len(self.images)

    def describe(self) -> dict:
        """JSON-able description for ``stack.json`` (no pixel data)."""
        return {"kind": self.kind, "names": list(self.names),
                "lit_fraction": [float(a) for a in self.lit_fraction],
                "complement_of": list(self.complement_of), **self.info}

    def save(self, folder: str | os.PathLike) -> Path:
        """Write 8-bit PNGs (``<name>.png``) and a ``stack.json`` into ``folder``."""
        from lumigraph.capture.io import write_image, write_stack_json

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        files = []
        for name, im in zip(self.names, self.images, strict=True):
            write_image(folder / f"{name}.png", np.round(im * 255.0).astype(np.uint8))
            files.append(f"{name}.png")
        h, w = self.images.shape[1:]
        write_stack_json(folder, files, projector_size=[w, h], pattern=self.describe())
        return folder


def _check_size(size) -> tuple[int, int]:
    w, h = (int(v) for v in size)
    if w < 1 or h < 1:
        raise ValueError(f"size: expected positive (width, height), got {size!r}")
    return w, h


def _grid(size):
    w, h = _check_size(size)
    return np.arange(w)[None, :], np.arange(h)[:, None], w, h


def checker_set(size, *, square: int = 8, shifts: int = 3) -> PatternSet:
    """Shifted binary checkerboards and their complements (Nayar 2006, Fig. 8.43).

    Parameters
    ----------
    size : (width, height)
        Projector resolution in pixels.
    square : int
        Checker square side in projector pixels; a positive multiple of
        ``shifts``.
    shifts : int
        Shift steps per axis, >= 1; the step is ``square // shifts`` pixels,
        so the ``shifts²`` shifted boards plus complements visit every phase.

    Raises
    ------
    InputError
        Naming ``shifts`` (< 1) or ``square`` (not a positive multiple of it).

    Returns
    -------
    PatternSet
        ``2·shifts²`` images: the shifted boards, then their complements.

    Examples
    --------
    >>> ps = checker_set((8, 4), square=2, shifts=1)
    >>> ps.images[0].astype(int).tolist()[0], ps.lit_fraction
    ([1, 1, 0, 0, 1, 1, 0, 0], (0.5, 0.5))
    """
    if shifts < 1:
        raise InputError("shifts", f"expected at least 1 shift step, got {shifts}")
    if square < 1 or square % shifts:
        raise InputError("square", f"must be a positive multiple of shifts, got square={square}, "
                                   f"shifts={shifts}")
    x, y, w, h = _grid(size)
    step = square // shifts
    boards, names, offs = [], [], []
    for j in range(shifts):
        for i in range(shifts):
            dx, dy = i * step, j * step
            on = (((x - dx) // square) + ((y - dy) // square)) % 2 == 0
            boards.append(on.astype(np.float32))
            offs.append([dx, dy])
    m = len(boards)
    images = np.stack(boards + [1.0 - b for b in boards]).astype(np.float32)
    names = tuple(f"checker_{k:02d}" for k in range(2 * m))
    comp = tuple(list(range(m, 2 * m)) + list(range(m)))
    alpha = tuple(float(a) for a in images.mean(axis=(1, 2)).round(6))
    return PatternSet("checker", images, names, alpha, comp,
                      {"square": square, "shifts": shifts, "step": step, "offsets": offs,
                       "period": 2 * square})


def block_set(size, *, alpha: float, tile: int = 8, cell: int = 1) -> PatternSet:
    """Binary patterns with lit fraction ``alpha``: in every ``tile×tile``-cell tile
    the ``round(alpha·tile²)`` cells nearest the tile centre are on; the set holds
    all ``tile²`` cyclic shifts by one cell, so every pixel is on in some images
    and off in others (the general-α case of eqs. 8.13–8.14).

    Parameters
    ----------
    size : (width, height)
        Projector resolution in pixels.
    alpha : float
        Lit fraction, in (0, 1) (:func:`check_lit_fraction`).
    tile : int
        Tile side in cells, >= 2.
    cell : int
        Cell side in projector pixels, >= 1.

    Raises
    ------
    InputError
        Naming the argument out of range.

    Examples
    --------
    >>> ps = block_set((8, 8), alpha=0.25, tile=4)
    >>> len(ps), ps.lit_fraction[0], ps.complement_of[0]
    (16, 0.25, -1)
    """
    check_lit_fraction(alpha)
    if tile < 2:
        raise InputError("tile", f"expected a tile of at least 2 cells, got {tile}")
    if cell < 1:
        raise InputError("cell", f"expected a cell of at least 1 pixel, got {cell}")
    m = int(round(alpha * tile * tile))
    m = min(max(m, 1), tile * tile - 1)
    ci, cj = np.meshgrid(np.arange(tile), np.arange(tile))
    d = (ci - (tile - 1) / 2.0) ** 2 + (cj - (tile - 1) / 2.0) ** 2
    order = np.lexsort((ci.ravel(), cj.ravel(), d.ravel()))
    motif = np.zeros(tile * tile, bool)
    motif[order[:m]] = True
    motif = motif.reshape(tile, tile)
    x, y, w, h = _grid(size)
    imgs, offs = [], []
    for j in range(tile):
        for i in range(tile):
            on = motif[((y // cell) - j) % tile, ((x // cell) - i) % tile]
            imgs.append(on.astype(np.float32))
            offs.append([i * cell, j * cell])
    images = np.stack(imgs)
    return PatternSet("block", images, tuple(f"block_{k:02d}" for k in range(len(imgs))),
                      tuple(float(a) for a in images.mean(axis=(1, 2)).round(6)),
                      (-1,) * len(imgs),
                      {"tile": tile, "cell": cell, "lit_cells": m, "alpha": m / tile ** 2,
                       "offsets": offs, "period": tile * cell})


def sinusoid_set(size, *, period: int = 8, cell: int = 1) -> PatternSet:
    """Three phase-shifted sinusoids ``0.5 + 0.5 cos(2π x/period + 2πk/3)``, k = 0, 1, 2
    (reference §8.3.4), constant over ``cell``-pixel columns (``x`` is the cell
    centre), so a pixel inside a cell sees an exact sinusoid in k.

    ``period`` (pixels) is at least 3 and a multiple of ``cell`` (>= 1);
    :class:`InputError` names the one out of range.

    Examples
    --------
    >>> ps = sinusoid_set((6, 2), period=6)
    >>> np.allclose(ps.images.sum(axis=0), 1.5)
    True
    """
    if cell < 1:
        raise InputError("cell", f"expected a cell of at least 1 pixel, got {cell}")
    if period < 3 or period % cell:
        raise InputError("period", f"expected >= 3 pixels, a multiple of cell, got period={period}, "
                                   f"cell={cell}")
    x, y, w, h = _grid(size)
    xc = (x // cell) * cell + (cell - 1) / 2.0
    imgs = [np.broadcast_to(0.5 + 0.5 * np.cos(2 * np.pi * xc / period + 2 * np.pi * k / 3),
                            (h, w)).astype(np.float32) for k in range(3)]
    return PatternSet("sinusoid", np.stack(imgs), ("sinusoid_0", "sinusoid_1", "sinusoid_2"),
                      (0.5, 0.5, 0.5), (-1, -1, -1),
                      {"period": period, "cell": cell, "phases": [0.0, 2 * np.pi / 3, 4 * np.pi / 3]})


def stripe_set(size, *, period: int = 8) -> PatternSet:
    """One image of vertical stripes, ``period // 2`` pixels on, the rest off
    (the single-image method, reference §8.3.4, Fig. 8.47). ``period`` is at
    least 2 pixels (:class:`InputError` naming it otherwise).

    Examples
    --------
    >>> stripe_set((8, 1), period=4).images[0, 0].astype(int).tolist()
    [1, 1, 0, 0, 1, 1, 0, 0]
    """
    if period < 2:
        raise InputError("period", f"expected >= 2 pixels, got {period}")
    x, y, w, h = _grid(size)
    on = np.broadcast_to((x % period) < period // 2, (h, w)).astype(np.float32)
    return PatternSet("stripe", on[None], ("stripe",), (float(on.mean()),), (-1,),
                      {"period": period, "lit": period // 2})


def occluder_set(size, *, period: int = 8, width: int = 1) -> PatternSet:
    """A shadow sweep: thin dark vertical bars ``width`` pixels wide, one every
    ``period`` pixels (a comb of thin occluders), moved one ``width`` step per
    image until every pixel has been in shadow once (reference §8.3.4, Fig. 8.46).
    ``width`` is at least 1 pixel and ``period`` a multiple of it, at least
    ``2·width``; :class:`InputError` names the one out of range.

    Examples
    --------
    >>> ps = occluder_set((4, 1), period=4)
    >>> len(ps), ps.images[:, 0].astype(int).tolist()[1]
    (4, [1, 0, 1, 1])
    """
    if width < 1:
        raise InputError("width", f"expected at least 1 pixel, got {width}")
    if period < 2 * width or period % width:
        raise InputError("period", f"expected >= 2*width, a multiple of width, got period={period}, "
                                   f"width={width}")
    x, y, w, h = _grid(size)
    imgs = [np.broadcast_to(((x - k * width) % period) >= width, (h, w)).astype(np.float32)
            for k in range(period // width)]
    images = np.stack(imgs)
    return PatternSet("occluder", images, tuple(f"occluder_{k:02d}" for k in range(len(imgs))),
                      tuple(float(a) for a in images.mean(axis=(1, 2)).round(6)),
                      (-1,) * len(imgs), {"period": period, "width": width})


def flat_set(size) -> PatternSet:
    """All-black and all-white frames (for measuring the black level ``b``).

    Examples
    --------
    >>> flat_set((2, 2)).names
    ('black', 'white')
    """
    w, h = _check_size(size)
    images = np.stack([np.zeros((h, w), np.float32), np.ones((h, w), np.float32)])
    return PatternSet("flat", images, ("black", "white"), (0.0, 1.0), (1, 0), {})


def emitted(pattern: np.ndarray, *, b: float = 0.0) -> np.ndarray:
    """Relative light a projector with black level ``b`` emits for ``pattern``:
    ``b + (1 - b)·pattern`` (off pixels leak a fraction ``b`` of on pixels).

    Examples
    --------
    >>> [round(float(v), 6) for v in emitted(np.array([0.0, 1.0]), b=0.1)]
    [0.1, 1.0]
    """
    if not 0.0 <= b < 1.0:
        raise ValueError(f"b: expected 0 <= b < 1, got {b}")
    return (b + (1.0 - b) * np.asarray(pattern, np.float64)).astype(np.float32)


def cell_weights(pattern: np.ndarray, *, cell: int, period_cells: int) -> np.ndarray:
    """Read a pattern as weights on the residue classes of a cell lattice.

    The projector image is cut into ``cell×cell``-pixel cells; cell ``(i, j)``
    belongs to class ``(i mod n, j mod n)`` with ``n = period_cells``. A pattern
    constant on cells and periodic with ``n`` cells is exactly
    ``Σ_c w[c]·1_c``, which lets a linear renderer compose it from one render
    per class.

    Returns
    -------
    ndarray, ``(n, n)`` float64
        ``w[j mod n, i mod n]``: the pattern's value on each class.

    Raises
    ------
    ValueError
        When the pattern is not constant on cells or not ``n``-periodic.

    Examples
    --------
    >>> ps = checker_set((8, 8), square=2, shifts=2)
    >>> cell_weights(ps.images[1], cell=1, period_cells=4)[0].tolist()
    [0.0, 1.0, 1.0, 0.0]
    """
    p = np.asarray(pattern, np.float64)
    h, w = p.shape
    n = int(period_cells)
    if h % cell or w % cell or (h // cell) % n or (w // cell) % n:
        raise ValueError(f"pattern: {w}x{h} is not a whole number of {n}-cell periods "
                         f"of {cell}-pixel cells")
    cells = p.reshape(h // cell, cell, w // cell, cell)
    if not np.all(cells == cells[:, :1, :, :1]):
        raise ValueError(f"pattern: not constant over {cell}x{cell}-pixel cells")
    c = cells[:, 0, :, 0]
    tiles = c.reshape(c.shape[0] // n, n, c.shape[1] // n, n)
    if not np.all(tiles == tiles[:1, :, :1, :]):
        raise ValueError(f"pattern: not periodic with {n} cells")
    return tiles[0, :, 0, :].copy()
