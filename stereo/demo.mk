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

# Facade's chain (Debevec, Taylor & Malik 1996), through a user's files: the
# building's photographs with blocks.json and edges.json -> solve (block
# parameters and camera poses) -> the solved model's depth from photo_03 (the
# key view) -> model-based stereo against photo_04 (the pilasters the block
# model lacks) -> a view-dependent rendering from a new viewpoint. The
# rendered scene is Lambertian: model-based stereo's SSD needs the two views
# to agree in brightness, which the glossy variant's highlights break.
$(OUT)/scenes/facade/stack.json: $(STAMP)
	$(LUMI) render facade --out $(@D) --size 640x480 --lambertian 1 --quiet

$(OUT)/stereo/facade/solve/model.json: $(OUT)/scenes/facade/stack.json
	$(LUMI) stereo facade solve $(<D) --out $(@D) --force --quiet

$(OUT)/stereo/facade/key_model.pfm: $(OUT)/stereo/facade/solve/model.json
	$(LUMI) stereo facade depth --model $< --camera $(<D)/cameras/photo_03.json --out $@ --quiet

$(OUT)/stereo/facade/rig.json: $(OUT)/stereo/facade/solve/model.json
	$(LUMI) stereo facade pair --key $(<D)/cameras/photo_03.json --offset $(<D)/cameras/photo_04.json \
	  --out $@ --quiet

$(OUT)/stereo/facade/key_refined.pfm: $(OUT)/stereo/facade/key_model.pfm $(OUT)/stereo/facade/rig.json
	$(LUMI) stereo model-based $(OUT)/scenes/facade/photo_03.png $(OUT)/scenes/facade/photo_04.png \
	  --rig $(OUT)/stereo/facade/rig.json --model $< --max-offset 0.5 --out $@ --quiet

$(OUT)/stereo/facade/view_1.png: $(OUT)/stereo/facade/solve/model.json $(OUT)/stereo/facade/key_refined.pfm
	$(LUMI) stereo facade render --model $< --photos $(OUT)/scenes/facade \
	  --view $(OUT)/scenes/facade/novel/view_1.json --out $@ --quiet

DEMO_OUTPUTS += $(OUT)/stereo/facade/key_model.pfm $(OUT)/stereo/facade/rig.json
DEMO_OUTPUTS += $(OUT)/stereo/facade/key_refined.pfm $(OUT)/stereo/facade/view_1.png
