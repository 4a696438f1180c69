# separation/: render the projector scene, separate it, and write the patterns.
# Included by the top-level Makefile; appends its final files to DEMO_OUTPUTS.

$(OUT)/scenes/projector/stack.json: $(STAMP)
	$(LUMI) render projector --out $(OUT)/scenes/projector --quiet

$(OUT)/separation/mask.png: $(OUT)/scenes/projector/stack.json
	$(LUMI) separate $(OUT)/scenes/projector --method checker --out $(OUT)/separation --quiet

$(OUT)/separation/sinusoid/mask.png: $(OUT)/scenes/projector/stack.json
	$(LUMI) separate $(OUT)/scenes/projector --method sinusoid --out $(OUT)/separation/sinusoid --quiet

$(OUT)/patterns/checker/stack.json: $(STAMP)
	$(LUMI) separate patterns --kind checker --size 1024x768 --square 8 --shifts 4 --out $(OUT)/patterns/checker --quiet

DEMO_OUTPUTS += $(OUT)/separation/mask.png $(OUT)/separation/sinusoid/mask.png $(OUT)/patterns/checker/stack.json

# Real data, when the shared folder has it: Nayar et al.'s moving-occluder video
# (CAVE), every 2nd frame, linearised with BT.709 (the command says so on stderr).
OCCLUDER_VIDEO := $(wildcard $(SHARED)/data/separation-cave-occluder/Red_Leaves.mpg)

$(OUT)/separation/red-leaves/mask.png: $(STAMP) $(OCCLUDER_VIDEO)
	$(LUMI) separate $(OCCLUDER_VIDEO) --method occluder --stride 2 --out $(@D) --quiet

DEMO_OUTPUTS += $(if $(OCCLUDER_VIDEO),$(OUT)/separation/red-leaves/mask.png)
