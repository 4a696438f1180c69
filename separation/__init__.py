"""Direct/global separation with high-frequency illumination (Nayar et al. 2006).

``separation.separate(images, method=...)`` returns a :class:`Separation`
(direct, global, mask) from linear images under projected patterns; the
methods live in :mod:`separation.nayar2006` and are registered in
:data:`separation.methods.METHODS` (the CLI's ``--method`` choices and help
come from there).

========== ================================================== ==============
method     input                                              images
========== ================================================== ==============
checker    shifted checkerboards and complements, any order    >= 2
sinusoid   three phase-shifted sinusoids                       3
single     one high-frequency stripe image                     1
occluder   a shadow sweep (thin occluder moved across)         >= 3
========== ================================================== ==============
"""

from lumigraph.separation.methods import METHODS, MIN_IMAGES
from lumigraph.separation.result import Separation
from lumigraph.separation.separate import separate

__all__ = ["METHODS", "MIN_IMAGES", "Separation", "separate"]
