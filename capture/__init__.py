"""Getting images in, and the plumbing every stage shares.

``capture`` is the root of lumigraph's import graph: every other stage may
import it, it imports none of them. It holds

- ``capture.io``: image and artifact formats (PNG/TIFF/JPEG with EXIF, RAW,
  OpenEXR, PFM, Middlebury ``.flo``, binary PLY) and image stacks;
- ``capture.headers``: image sizes read from file headers, checked against
  the pixel limit (``LUMIGRAPH_MAX_PIXELS``) before any decoder allocates;
- ``capture.artifact``: atomic writes and the ``<output>.meta.json`` sidecar;
- ``capture.errors``: the exceptions the command line turns into exit 2;
- ``capture.commandline``: the ``lumigraph`` command and the CLI helpers;
- ``capture.bench``: the speed-against-error harness (``lumigraph bench``);
- ``capture.render`` and ``capture.scenes``: synthetic scenes with exact
  ground truth (``lumigraph render``).

Importing ``capture`` is cheap on purpose: ``make`` starts Python once per
stage, so heavy libraries are imported inside the functions that use them.
"""

