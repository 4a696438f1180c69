"""Correspondence and geometry: optical flow, Sand–Teller video matching,
semi-global and block-matching stereo, triangulation, multi-view SfM and model-based stereo."""
