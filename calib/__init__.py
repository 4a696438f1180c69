"""Camera calibration: camera model, target detection, intrinsics and
distortion (Zhang), stereo rigs, rectification and undistortion."""
