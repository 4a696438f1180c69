# HDR demo: bracket -> response.json + curve plot -> radiance.exr -> tone-mapped PNG.

HDR_OUT := $(OUT)/hdr

$(OUT)/scenes/bracket/stack.json: $(STAMP)
	$(LUMI) render bracket --out $(OUT)/scenes/bracket --size 320x240 --quiet

$(HDR_OUT)/response.json $(HDR_OUT)/curve.png &: $(OUT)/scenes/bracket/stack.json
	$(LUMI) hdr response $(OUT)/scenes/bracket --method debevec --out $(HDR_OUT)/response.json \
	  --plot $(HDR_OUT)/curve.png --quiet

$(HDR_OUT)/radiance.exr: $(HDR_OUT)/response.json
	$(LUMI) hdr merge $(OUT)/scenes/bracket --response $< --out $@ --quiet

$(HDR_OUT)/tonemapped.png: $(HDR_OUT)/radiance.exr
	$(LUMI) hdr tonemap $< --method reinhard-local --out $@ --quiet

$(HDR_OUT)/radiance.hdr: $(HDR_OUT)/radiance.exr
	$(LUMI) hdr convert $< $@ --quiet

DEMO_OUTPUTS += $(HDR_OUT)/curve.png $(HDR_OUT)/tonemapped.png $(HDR_OUT)/radiance.hdr
