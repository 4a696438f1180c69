# stereo demo, through the files a user would have (no ground truth goes in):
# the pair -> calib/demo.mk's rig.json (from board photos of the same rig) ->
# rectification.json -> disparity.pfm -> points.ply (coloured, metres).
$(OUT)/scenes/stereo-pair/stack.json: $(STAMP)
	$(LUMI) render stereo-pair --out $(@D) --layout $(STEREO_PAIR_LAYOUT) $(STEREO_PAIR_GEOMETRY) \
	  --quiet

$(OUT)/stereo/disparity.pfm: $(OUT)/scenes/stereo-pair/stack.json $(OUT)/calib/rectified/rectification.json
	$(LUMI) stereo match $(<D)/left.png $(<D)/right.png --rectification $(word 2,$^) \
	  --max-disp 47 --out $@ --quiet

$(OUT)/stereo/points.ply: $(OUT)/stereo/disparity.pfm $(OUT)/calib/rectified/rectification.json \
  $(OUT)/scenes/stereo-pair/stack.json
	$(LUMI) stereo depth $< --rectification $(word 2,$^) \
	  --image $(OUT)/scenes/stereo-pair/left.png --out $@ --quiet

DEMO_OUTPUTS += $(OUT)/stereo/disparity.pfm $(OUT)/stereo/points.ply

# model-based stereo (Debevec, Taylor & Malik 1996): facade with relief, rough model = wall plane.
# No demo step computes either input: the wide-baseline key/offset rig has no
# board photos to calibrate it from, and the rough model stands for one built
# by hand (Facade) from the photos; the scene's gt.json rig and gt/model_depth.npy
# take their place.
$(OUT)/scenes/model-stereo/stack.json: $(STAMP)
	$(LUMI) render model-stereo --out $(OUT)/scenes/model-stereo --quiet

$(OUT)/stereo/facade_depth.pfm $(OUT)/stereo/facade_warped.png &: $(OUT)/scenes/model-stereo/stack.json
	$(LUMI) stereo model-based $(OUT)/scenes/model-stereo/key.png $(OUT)/scenes/model-stereo/offset.png \
	  --rig $(OUT)/scenes/model-stereo/gt.json --model $(OUT)/scenes/model-stereo/gt/model_depth.npy \
	  --max-offset 0.35 --warped $(OUT)/stereo/facade_warped.png --out $(OUT)/stereo/facade_depth.pfm \
	  --quiet

DEMO_OUTPUTS += $(OUT)/stereo/facade_depth.pfm
# every file a grouped step writes, so a rerun rebuilds whichever a kill left missing
DEMO_OUTPUTS += $(OUT)/stereo/facade_warped.png
