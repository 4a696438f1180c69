"""Scene renderers, one module per family of scenes (see ``capture.render``).

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
=====================  ==========================================================
"""
