"""Façade (Debevec, Taylor & Malik 1996, doi:10.1145/237170.237191): the three
stages of model-based reconstruction of reference ch. 5, §5.3.2.

Modules
-------
``model``         the block model (``blocks.json``): :class:`BlockModel`,
                  :func:`load_blocks`, :class:`Mesh`.
``polygon``       the ``extrusion`` block's polygon: coordinate expressions,
                  the simplicity test, the cap triangulation.
``edges``         the marked image edges (``edges.json``).
``solve``         photogrammetric modelling: block parameters and camera poses
                  from the marked edges (eqs. 5.3–5.5).
``automark``      automatic edge marking from a rough model and rough cameras.
``model_stereo``  stage 3, model-based stereo (:func:`model_stereo`).
``vdtm``          stage 2, view-dependent texture mapping (:func:`render_vdtm`).
``reflection``    a reflection layer at infinity for VDTM's blend on glossy
                  planes (:func:`fit_reflection_layer`; beyond the paper).

The model API (stage 1)
-----------------------
``load_blocks(path) -> BlockModel``; ``BlockModel.from_dict(d, where=path)``;
``BlockModel.to_dict()``.

``BlockModel.parameter_names``: the free parameters (``block/param``, or a
global parameter's own name), in the order the array forms below take.
``BlockModel.all_parameter_names``: every name, shared and fixed ones too.
``BlockModel.named_values(params)``: every name -> value.

Each geometry call takes ``params``: None (the model's own values), an array
of the free parameters, or a mapping ``{name: value}``:

- ``BlockModel.mesh(params) -> Mesh(vertices (N, 3) float64, faces (M, 3)
  int64 counter-clockwise seen from outside, face_block (M,) block names)``;
- ``BlockModel.edges(params) -> {"block/edge": (p0 (3,), p1 (3,))}`` in world
  coordinates (z up, ground z = 0, the root block centred on the origin);
- ``BlockModel.edge_matrices(names) -> (C0, C1)``, ``(E, 3, S)``: endpoints
  are linear in the slot values (``BlockModel.slot_vector(params)``), so the
  derivatives are these constant matrices;
- ``BlockModel.with_values(params)``: the model with fitted values.

>>> from lumigraph.stereo.debevec1996 import BlockModel
>>> m = BlockModel.from_dict({"blocks": [{"name": "b", "kind": "box",
...     "params": {"width": {"value": 2, "fixed": True}, "depth": 1, "height": 3}}]})
>>> m.edges()["b/top-front"]
(array([-1. , -0.5,  3. ]), array([ 1. , -0.5,  3. ]))
"""

from lumigraph.stereo.debevec1996.model import Block, BlockModel, Mesh, load_blocks, save_blocks
from lumigraph.stereo.debevec1996.model_stereo import (
    MAX_STEPS,
    WINDOW_RANGE,
    ModelStereo,
    check_model_stereo_options,
    key_rays,
    model_in_offset_view,
    model_stereo,
    warp_offset,
)

__all__ = [
    "MAX_STEPS", "WINDOW_RANGE", "Block", "BlockModel", "Mesh", "ModelStereo",
    "check_model_stereo_options", "key_rays", "load_blocks", "model_in_offset_view",
    "model_stereo", "save_blocks", "warp_offset",
]
