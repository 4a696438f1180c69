"""Scene renderers, one module per family of scenes (see ``lumigraph.capture.render``).

Each scene is an entry of ``lumigraph.capture.render.SCENES`` (name -> renderer,
summary); its module keeps the scene's data, a ``SceneSpec`` (default size,
option table, cache version), in ``SPECS`` under the same name.

=====================  ==========================================================
module                 scenes
=====================  ==========================================================
``sample``             a linear radiance ramp (smoke test of the plumbing)
``boards``             checkerboard/ChArUco calibration views, stereo rigs
``brackets``           HDR exposure brackets through known responses, HDR video
``flow``               2-frame and N-frame sequences with exact forward flow
``stereo``             rectified/unrectified pairs and multi-view sets with exact geometry
``lightfield``         camera arrays, thin-lens refocus truth, lenslet raws
``projector``          projector-lit stacks with direct/global truth (Mitsuba)
``model_stereo``       a facade's key/offset views and its rough model
=====================  ==========================================================
"""
