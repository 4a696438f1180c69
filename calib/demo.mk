# Calibration demo: render checkerboard views -> camera.json (auto model, with
# OpenCV YAML and COLMAP exports) -> undistorted images; render a stereo rig's
# board views -> rig.json -> the stereo pair of stereo/ rectified with it.
#   $(OUT)/calib/camera.json          one camera (K, dist, std, views, candidates, warnings)
#   $(OUT)/calib/undistorted/         undistorted PNGs + camera.json (no distortion)
#   $(OUT)/calib/rig.json             stereo rig (left, right, R, T, E, F), T in metres
#   $(OUT)/calib/rectified/           the stereo pair rectified: left.png, right.png,
#                                     maps_*.npy, rectification.json (stereo/ uses it)
#
# The stereo boards and the stereo pair share one rig: the boards are rendered
# with the stereo-pair scene's cameras and pose (--rig stereo-pair-...) at the
# pair's size and baseline, with the board in the pair's metres, so the rig
# calibrated here is the rig of the pair stereo/ matches. stereo/demo.mk renders
# the pair with the same two settings.
STEREO_PAIR_LAYOUT := unrectified
STEREO_PAIR_GEOMETRY := --size 320x240 --baseline 0.18
STEREO_BOARD := checker:10x7:0.06

$(OUT)/scenes/boards/stack.json: $(STAMP)
	$(LUMI) render boards --out $(@D) --size 640x480 --quiet

$(OUT)/scenes/boards-stereo/stack.json: $(STAMP)
	$(LUMI) render boards-stereo --out $(@D) --rig stereo-pair-$(STEREO_PAIR_LAYOUT) \
	  $(STEREO_PAIR_GEOMETRY) --distortion none --square $(lastword $(subst :, ,$(STEREO_BOARD))) \
	  --quiet

$(OUT)/calib/camera.json $(OUT)/calib/camera.yml $(OUT)/calib/cameras.txt &: $(OUT)/scenes/boards/stack.json
	$(LUMI) calib calibrate $(<D) --out $(OUT)/calib/camera.json --yaml $(OUT)/calib/camera.yml \
	  --colmap $(OUT)/calib/cameras.txt --quiet

$(OUT)/calib/undistorted/undistorted.json: $(OUT)/calib/camera.json $(OUT)/scenes/boards/stack.json
	$(LUMI) calib undistort --camera $< $(OUT)/scenes/boards --out $(@D) --quiet

$(OUT)/calib/rig.json $(OUT)/calib/rig.yml &: $(OUT)/scenes/boards-stereo/stack.json
	$(LUMI) calib stereo --left $(<D)/left_*.png --right $(<D)/right_*.png --out $(OUT)/calib/rig.json \
	  --board $(STEREO_BOARD) --yaml $(OUT)/calib/rig.yml --quiet

$(OUT)/calib/rectified/rectification.json: $(OUT)/calib/rig.json $(OUT)/scenes/stereo-pair/stack.json
	$(LUMI) calib rectify --rig $< $(OUT)/scenes/stereo-pair/left.png \
	  $(OUT)/scenes/stereo-pair/right.png --out $(@D) --quiet

DEMO_OUTPUTS += $(OUT)/calib/camera.json $(OUT)/calib/undistorted/undistorted.json \
  $(OUT)/calib/rectified/rectification.json
# every file a grouped step writes, so a rerun rebuilds whichever a kill left missing
DEMO_OUTPUTS += $(OUT)/calib/camera.yml $(OUT)/calib/cameras.txt $(OUT)/calib/rig.yml
