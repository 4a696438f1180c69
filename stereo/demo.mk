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
