# HDR demo: bracket -> response.json + curve plot -> radiance.exr -> tone-mapped PNG.

HDR_OUT := $(OUT)/hdr

$(OUT)/scenes/bracket/stack.json: $(STAMP)
	$(LUMI) render bracket --out $(OUT)/scenes/bracket --size 320x240 --quiet

$(HDR_OUT)/response.json $(HDR_OUT)/curve.png &: $(OUT)/scenes/bracket/stack.json
	$(LUMI) hdr response $(OUT)/scenes/bracket --method debevec --out $(HDR_OUT)/response.json \
	  --plot $(HDR_OUT)/curve.png --quiet

$(HDR_OUT)/radiance.exr $(HDR_OUT)/radiance.mask.png &: $(HDR_OUT)/response.json
	$(LUMI) hdr merge $(OUT)/scenes/bracket --response $< --out $(HDR_OUT)/radiance.exr --quiet

$(HDR_OUT)/tonemapped.png: $(HDR_OUT)/radiance.exr
	$(LUMI) hdr tonemap $< --method reinhard-local --out $@ --quiet

$(HDR_OUT)/radiance.hdr: $(HDR_OUT)/radiance.exr
	$(LUMI) hdr convert $< $@ --quiet

DEMO_OUTPUTS += $(HDR_OUT)/curve.png $(HDR_OUT)/tonemapped.png $(HDR_OUT)/radiance.hdr

# HDR video (Kang et al. 2003): alternating exposures, the same film camera as the
# bracket, so its recovered response.json applies.
$(OUT)/scenes/bracket_video/stack.json: $(STAMP)
	$(LUMI) render bracket_video --out $(OUT)/scenes/bracket_video --size 160x120 --frames 6 --quiet

$(HDR_OUT)/video/video.meta.json: $(OUT)/scenes/bracket_video/stack.json $(HDR_OUT)/response.json
	$(LUMI) hdr video $(OUT)/scenes/bracket_video --response $(HDR_OUT)/response.json \
	  --out $(HDR_OUT)/video --tonemap --quiet

DEMO_OUTPUTS += $(HDR_OUT)/video/video.meta.json
# every file a grouped step writes, so a rerun rebuilds whichever a kill left missing
DEMO_OUTPUTS += $(HDR_OUT)/radiance.mask.png
