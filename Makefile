# lumigraph — build, test, demo and bench.
#
#   make demo    set up .venv, render the synthetic scenes, run every stage
#                through files into out/, print where the results are
#   make test    the full test suite (what CI runs)
#   make bench   the speed-against-error report in out/bench/
#   make bench-gpu  the torch/kornia ports on a CUDA GPU (out/bench-gpu/)
#
# Stage targets chain through real files in out/, so make redoes only what
# changed and `make -j2` is safe. Each stage adds its demo steps in
# <stage>/demo.mk (included below) and appends its final files to DEMO_OUTPUTS.

SHELL      := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DELETE_ON_ERROR:
.SUFFIXES:

PYTHON     ?= python3
VENV       := .venv
PY         := $(VENV)/bin/python
LUMI       := $(VENV)/bin/lumigraph
STAMP      := $(VENV)/.installed
OUT        := out
SHARED     ?= $(abspath ../shared)
SYSTOOLS   := pfshdrcalibrate exrheader tiffinfo chromium chromedriver
APT_PKGS   := pfstools openexr libtiff-tools chromium chromium-driver
PYTEST_ARGS ?=
# One BLAS thread per process: the tests run two xdist workers on two cores and
# the bench times methods side by side; threaded BLAS on small least-squares
# problems oversubscribes the cores and made some solves 30x slower.
BLAS1      := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1

.PHONY: all venv sysdeps test demo bench bench-gpu clean lint
all: demo

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev,gpu]'
	touch $@

# System tools used as peers and independent readers (pfstools, OpenEXR's
# exrheader, libtiff), and the headless browser of `lumigraph view`'s page test
# (Chromium and its chromedriver). Installed when missing and we are root; otherwise the
# tests that need them say which package to install.
sysdeps:
	@missing=""; for t in $(SYSTOOLS); do command -v $$t >/dev/null || missing="$$missing $$t"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing system tools ($(APT_PKGS)) for:$$missing"; \
	    DEBIAN_FRONTEND=noninteractive apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $(APT_PKGS) >/dev/null; \
	  else echo "note: missing$$missing; install Debian packages: $(APT_PKGS)"; fi; \
	fi



# Unit, property, hard-case and end-to-end tests, plus every docstring example.
test: $(STAMP) sysdeps
	$(BLAS1) $(PY) -m pytest -n 2 tests $(PYTEST_ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check .

bench: $(STAMP) sysdeps
	$(BLAS1) $(LUMI) bench --out $(OUT)/bench

# The torch/kornia ports on the GPU beside our CPU code, with the issue's speed
# targets (exit 2 on a machine where torch sees no CUDA GPU).
bench-gpu: $(STAMP)
	$(BLAS1) $(LUMI) bench gpu --device cuda --out $(OUT)/bench-gpu

clean:
	rm -rf $(OUT) .pytest_cache

# ---------------------------------------------------------------- demo chain
DEMO_OUTPUTS :=

# The plumbing's own smoke test: a rendered scene, described by `inspect`.
$(OUT)/scenes/sample/stack.json: $(STAMP)
	$(LUMI) render sample --out $(@D) --noise 2 --quiet

$(OUT)/sample/summary.json: $(OUT)/scenes/sample/stack.json
	$(LUMI) inspect $(<D) --out $@ --quiet

DEMO_OUTPUTS += $(OUT)/sample/summary.json

-include capture/demo.mk calib/demo.mk hdr/demo.mk stereo/flow.mk stereo/demo.mk lightfield/demo.mk separation/demo.mk

demo: $(STAMP) $(DEMO_OUTPUTS)
	@echo
	@echo "demo outputs (each with its .meta.json beside it):"
	@for f in $(DEMO_OUTPUTS); do echo "  $$f"; done
	@echo "open out/ to look at them; 'make bench' writes out/bench/report.md"
