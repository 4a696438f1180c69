# Flow demo: render a 2-frame sequence with exact flow, estimate the flow
# (pyramid) and a Sand-Teller video match, with Middlebury-coloured pictures.

$(OUT)/scenes/flow/stack.json: $(STAMP)
	$(LUMI) render flow --out $(@D) --quiet

$(OUT)/scenes/flow-video/stack.json: $(STAMP)
	$(LUMI) render flow-video --out $(@D) --quiet

$(OUT)/flow/flow.flo $(OUT)/flow/flow.png &: $(OUT)/scenes/flow/stack.json
	$(LUMI) flow $(<D)/frame00.png $(<D)/frame01.png --out $(OUT)/flow/flow.flo --viz $(OUT)/flow/flow.png --quiet

$(OUT)/flow/video-match.flo $(OUT)/flow/video-match.png &: $(OUT)/scenes/flow-video/stack.json
	$(LUMI) flow $(<D)/frame00.png $(<D)/frame01.png --method video-matching \
	  --out $(OUT)/flow/video-match.flo --viz $(OUT)/flow/video-match.png --quiet

DEMO_OUTPUTS += $(OUT)/flow/flow.flo $(OUT)/flow/video-match.flo

# A 5-frame sequence: one flow per consecutive pair, with an index.json.
$(OUT)/scenes/flow-sequence/stack.json: $(STAMP)
	$(LUMI) render flow-sequence --out $(@D) --quiet

$(OUT)/flow/sequence/index.json: $(OUT)/scenes/flow-sequence/stack.json
	$(LUMI) flow $(<D)/frame0*.png --out $(@D) --viz $(@D)/pictures --quiet

DEMO_OUTPUTS += $(OUT)/flow/sequence/index.json
# every file a grouped step writes, so a rerun rebuilds whichever a kill left missing
DEMO_OUTPUTS += $(OUT)/flow/flow.png $(OUT)/flow/video-match.png
