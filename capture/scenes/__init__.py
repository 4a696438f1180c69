"""Scene renderers, one module per family of scenes (see ``capture.render``).

=====================  ==========================================================
module                 scenes
=====================  ==========================================================
``sample``             a linear radiance ramp (smoke test of the plumbing)
``boards``             checkerboard/ChArUco calibration views, stereo rigs
``brackets``           HDR exposure brackets through known responses, HDR video
``motion``             stereo pairs and flow sequences with exact disparity/flow
``lightfield``         camera arrays, thin-lens refocus truth, lenslet raws
``projector``          projector-lit stacks with direct/global truth (Mitsuba)
=====================  ==========================================================
"""
