"""The stage's method registry: the ``--method`` names of ``lumigraph separate``,
the estimator each runs (:mod:`separation.nayar2006`), a one-line help, the
options it understands, and how many images it takes.

The CLI's ``choices`` and help lines are generated from :data:`METHODS`, and
:func:`separation.separate` dispatches through it.

Examples
--------
>>> METHODS.names
('checker', 'sinusoid', 'single', 'occluder')
>>> METHODS.resolve("single").load().__name__, MIN_IMAGES["single"], EXACT_IMAGES["single"]
('single', 1, 1)
"""

from __future__ import annotations

from lumigraph.capture.registry import Method, Registry

MIN_IMAGES = {"checker": 2, "sinusoid": 3, "single": 1, "occluder": 3}
EXACT_IMAGES = {"sinusoid": 3, "single": 1}


def _images(name: str) -> str:
    n = EXACT_IMAGES.get(name)
    return f"{n} image{'' if n == 1 else 's'}" if n else f">= {MIN_IMAGES[name]} images"


METHODS = Registry("separation", [
    Method("checker", "lumigraph.separation.nayar2006:checker",
           f"shifted checkerboards and their complements, any order ({_images('checker')})",
           options=("alpha", "b", "complement_of", "estimator", "sigma")),
    Method("sinusoid", "lumigraph.separation.nayar2006:sinusoid",
           f"three phase-shifted sinusoids ({_images('sinusoid')})", options=("b",)),
    Method("single", "lumigraph.separation.nayar2006:single",
           f"one high-frequency stripe image ({_images('single')})",
           options=("alpha", "b", "tile")),
    Method("occluder", "lumigraph.separation.nayar2006:occluder",
           f"a shadow sweep of a thin occluder ({_images('occluder')})", options=("alpha", "b")),
])
