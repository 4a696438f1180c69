# lightfield/: camera-array light field -> refocus (one + focal stack) -> novel
# view -> depth; lenslet raw -> decoded sub-aperture views. Included by the Makefile.
# Upstream artifacts: every step after import reads the computed lightfield.json.
# Import itself has no upstream step to use: the array's grid, spacing and focal
# length come with the capture (the rendered folder's stack.json, as an array
# rig's spec sheet would; the array is ideal, so no --rig), and no demo step
# calibrates the array's cameras (calib/camera.json is another camera). The
# lenslet decode fits its grid from the white image itself.

$(OUT)/scenes/lightfield-array/stack.json: $(STAMP)
	$(LUMI) render lightfield-array --out $(@D) --size 160x120 --quiet

$(OUT)/scenes/lightfield-lenslet-hex/stack.json: $(STAMP)
	$(LUMI) render lightfield-lenslet-hex --out $(@D) --quiet

$(OUT)/lightfield/array/lightfield.json: $(OUT)/scenes/lightfield-array/stack.json
	$(LUMI) lightfield import $(<D) --out $(@D) --quiet

$(OUT)/lightfield/refocus-near.exr: $(OUT)/lightfield/array/lightfield.json
	$(LUMI) lightfield refocus $(<D) --slope 1.0 --method shift-add --out $@ --quiet

$(OUT)/lightfield/focal-stack/index.json: $(OUT)/lightfield/array/lightfield.json
	$(LUMI) lightfield refocus $(<D) --slope 0,0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8,0.9,1.0 \
	  --method auto --out $(@D) --quiet

$(OUT)/lightfield/novel-view.exr: $(OUT)/lightfield/array/lightfield.json
	$(LUMI) lightfield render $(<D) --position 0.5 0.5 0 --focus-slope 0.6 --out $@ --quiet

$(OUT)/lightfield/disparity.pfm $(OUT)/lightfield/all-in-focus.exr &: $(OUT)/lightfield/array/lightfield.json
	$(LUMI) lightfield depth $(<D) --slopes 0,1.2,25 --all-in-focus $(OUT)/lightfield/all-in-focus.exr \
	  --out $(OUT)/lightfield/disparity.pfm --quiet

$(OUT)/lightfield/lenslet/lightfield.json: $(OUT)/scenes/lightfield-lenslet-hex/stack.json
	$(LUMI) lightfield decode $(<D)/raw.png --white $(<D)/white.png --out $(@D) --quiet

# Real data: the HCI "antinous" 5x5 views (sRGB PNG, row-major by file name); the
# data set ships no camera files, so spacing is one view step (no upstream step).
HCI_VIEWS := $(sort $(wildcard $(SHARED)/data/lightfield-real/hci_antinous_5x5/input_Cam*.png))

$(OUT)/lightfield/hci/lightfield.json: $(STAMP) $(HCI_VIEWS)
	$(LUMI) lightfield import $(HCI_VIEWS) --grid 5x5 --spacing 1 --out $(@D) --quiet

$(OUT)/lightfield/hci-refocus/index.json: $(OUT)/lightfield/hci/lightfield.json
	$(LUMI) lightfield refocus $(<D) --slope=-1.5,0,1.5 --method shift-add --out $(@D) --quiet

DEMO_OUTPUTS += $(if $(HCI_VIEWS),$(OUT)/lightfield/hci-refocus/index.json)
DEMO_OUTPUTS += $(OUT)/lightfield/refocus-near.exr $(OUT)/lightfield/focal-stack/index.json \
  $(OUT)/lightfield/novel-view.exr $(OUT)/lightfield/disparity.pfm \
  $(OUT)/lightfield/lenslet/lightfield.json
# every file a grouped step writes, so a rerun rebuilds whichever a kill left missing
DEMO_OUTPUTS += $(OUT)/lightfield/all-in-focus.exr
