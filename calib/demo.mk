# Calibration demo: render checkerboard views -> camera.json (auto model, with
# OpenCV YAML and COLMAP exports) -> undistorted images; render a stereo rig ->
# rig.json -> a rectified pair (rows = epipolar lines) for stereo/.
#   $(OUT)/calib/camera.json          one camera (K, dist, std, views, candidates, warnings)
#   $(OUT)/calib/undistorted/         undistorted PNGs + camera.json (no distortion)
#   $(OUT)/calib/rig.json             stereo rig (left, right, R, T, E, F), T in mm
#   $(OUT)/calib/rectified/           left.png, right.png, maps_*.npy, rectification.json

$(OUT)/scenes/boards/stack.json: $(STAMP)
	$(LUMI) render boards --out $(@D) --size 640x480 --quiet

$(OUT)/scenes/boards-stereo/stack.json: $(STAMP)
	$(LUMI) render boards-stereo --out $(@D) --size 640x480 --quiet

$(OUT)/calib/camera.json: $(OUT)/scenes/boards/stack.json
	$(LUMI) calib calibrate $(<D) --out $@ --yaml $(@D)/camera.yml --colmap $(@D)/cameras.txt --quiet

$(OUT)/calib/undistorted/undistorted.json: $(OUT)/calib/camera.json $(OUT)/scenes/boards/stack.json
	$(LUMI) calib undistort --camera $< $(OUT)/scenes/boards --out $(@D) --quiet

$(OUT)/calib/rig.json: $(OUT)/scenes/boards-stereo/stack.json
	$(LUMI) calib stereo --left $(<D)/left_*.png --right $(<D)/right_*.png --out $@ \
	  --board checker:10x7:30 --yaml $(@D)/rig.yml --quiet

$(OUT)/calib/rectified/rectification.json: $(OUT)/calib/rig.json $(OUT)/scenes/boards-stereo/stack.json
	$(LUMI) calib rectify --rig $< $(OUT)/scenes/boards-stereo/left_00.png \
	  $(OUT)/scenes/boards-stereo/right_00.png --out $(@D) --quiet

DEMO_OUTPUTS += $(OUT)/calib/camera.json $(OUT)/calib/undistorted/undistorted.json \
  $(OUT)/calib/rectified/rectification.json
