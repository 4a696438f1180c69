# stereo demo: rectified pair -> disparity.pfm -> points.ply (coloured)
$(OUT)/scenes/stereo-pair/stack.json: $(STAMP)
	$(LUMI) render stereo-pair --out $(OUT)/scenes/stereo-pair --quiet

$(OUT)/stereo/disparity.pfm: $(OUT)/scenes/stereo-pair/stack.json
	$(LUMI) stereo match $(OUT)/scenes/stereo-pair/left.png $(OUT)/scenes/stereo-pair/right.png \
	  --max-disp 47 --out $@ --quiet

$(OUT)/stereo/points.ply: $(OUT)/stereo/disparity.pfm
	$(LUMI) stereo depth $< --rig $(OUT)/scenes/stereo-pair/gt.json \
	  --image $(OUT)/scenes/stereo-pair/left.png --out $@ --quiet

DEMO_OUTPUTS += $(OUT)/stereo/disparity.pfm $(OUT)/stereo/points.ply

# model-based stereo (Debevec, Taylor & Malik 1996): facade with relief, rough model = wall plane
$(OUT)/scenes/model-stereo/stack.json: $(STAMP)
	$(LUMI) render model-stereo --out $(OUT)/scenes/model-stereo --quiet

$(OUT)/stereo/facade_depth.pfm: $(OUT)/scenes/model-stereo/stack.json
	$(LUMI) stereo model-based $(OUT)/scenes/model-stereo/key.png $(OUT)/scenes/model-stereo/offset.png \
	  --rig $(OUT)/scenes/model-stereo/gt.json --model $(OUT)/scenes/model-stereo/gt/model_depth.npy \
	  --max-offset 0.35 --warped $(OUT)/stereo/facade_warped.png --out $@ --quiet

DEMO_OUTPUTS += $(OUT)/stereo/facade_depth.pfm
