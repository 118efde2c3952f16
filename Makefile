# make demo  - run the main job on the built-in example and write out/
# make test  - the whole test suite on Blender 5.0.1 and 5.2.3, the smoke subset on 4.5 LTS and 4.2 LTS
# make test-core - the bpy-free tests only (Blender 5.0.1's venv)
# make fuzz - hypothesis fuzzing of every operator: >= 1,000 random surfaces and parameters (Blender 5.0.1)
# make bench - benchmarks (printed, not asserted), their tables written to docs/benchmarks.md
# make pictures - the README's step-by-step pictures in docs/img/ (scripts/readme_pictures.py)
# make extension - the installable extension zip in dist/ (Blender's own builder, from bpy)
# make house - packages, modules, import cycles, the longest modules and functions (scripts/house.py)
# make operators-doc - docs/operators.md from the registered operators (scripts/operators_doc.py)
# make extension-wheels - one zip per platform in dist/, with scipy, scikit-learn, manifold3d and libigl (cp311 and cp313) inside
#
# One venv per Blender, each from its pinned requirements file and stamped .installed:
#   .venv/   bpy 5.0.1, Python 3.11, numpy 1.26  requirements.txt       whole suite
#   .venv52/ bpy 5.2.3, Python 3.13, numpy 2     requirements-bpy52.txt whole suite
#   .venv45/ bpy 4.5 LTS, Python 3.11            requirements-bpy45.txt smoke subset
#   .venv42/ bpy 4.2.0 LTS, Python 3.11          requirements-bpy42.txt smoke subset

# A *working* interpreter of the given version: a pyenv shim on PATH fails unless pyenv selects
# that version, so every candidate (PATH, pyenv's versions/X.Y.*, /usr/local/bin, /usr/bin) must
# answer --version with it.
# (${shell ...}: the braces let the shell's `case ... )` through.)
find_python = ${shell for p in python$(1) $$(pyenv root 2>/dev/null || echo "$${PYENV_ROOT:-$$HOME/.pyenv}")/versions/$(1).*/bin/python$(1) \
	/usr/local/bin/python$(1) /usr/bin/python$(1); do \
	case "$$($$p --version 2>/dev/null)" in "Python $(1)."*) command -v $$p; break;; esac; done}
ifeq ($(origin PYTHON),undefined)
PYTHON := $(or $(call find_python,3.11),$(shell command -v python3))
endif
ifeq ($(origin PYTHON313),undefined)
PYTHON313 := $(call find_python,3.13)
endif

VENV   := .venv
VENV52 := .venv52
VENV45 := .venv45
VENV42 := .venv42
PY     := $(VENV)/bin/python
PY52   := $(VENV52)/bin/python
PY45   := $(VENV45)/bin/python
PY42   := $(VENV42)/bin/python
PIP_INSTALL := -m pip install --quiet --disable-pip-version-check
NO_PY313 := SKIPPED: the Blender 5.2.3 run (.venv52) -- no working Python 3.13 found (python3.13 on PATH, \
pyenv's versions/3.13.*, /usr/local/bin, /usr/bin); install one or pass PYTHON313=/path/to/python3.13

# The venvs `make test` needs are built side by side (pip downloads, one per venv).
MAKEFLAGS += -j2

.PHONY: demo pictures test test-core fuzz bench extension extension-wheels house operators-doc clean

$(VENV)/.installed: requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) $(PIP_INSTALL) -r requirements.txt
	touch $@

$(VENV52)/.installed: requirements-bpy52.txt
	@test -x $(PY52) || test -n "$(PYTHON313)" || { echo "$(NO_PY313)"; exit 1; }
	test -x $(PY52) || $(PYTHON313) -m venv $(VENV52)
	$(PY52) $(PIP_INSTALL) -r requirements-bpy52.txt
	touch $@

$(VENV45)/.installed: requirements-bpy45.txt
	test -x $(PY45) || $(PYTHON) -m venv $(VENV45)
	$(PY45) $(PIP_INSTALL) -r requirements-bpy45.txt
	touch $@

$(VENV42)/.installed: requirements-bpy42.txt
	test -x $(PY42) || $(PYTHON) -m venv $(VENV42)
	$(PY42) $(PIP_INSTALL) -r requirements-bpy42.txt
	touch $@

demo: $(VENV)/.installed
	$(PY) scripts/demo.py --out out

pictures: $(VENV)/.installed
	$(PY) scripts/readme_pictures.py --out docs/img

# The runs go two at a time on their own temporary folders (scripts/run_suites.py: two cores, so
# the two whole suites take about as long as the slower one alone); every run goes ahead even when
# another failed, each prints its log whole when it ends, and the target fails if any did.
test: $(VENV)/.installed $(VENV45)/.installed $(VENV42)/.installed $(if $(PYTHON313),$(VENV52)/.installed)
	@$(if $(PYTHON313),,echo "$(NO_PY313)";) $(PY) scripts/run_suites.py --jobs 2 \
	  "Blender 5.0.1 (Python 3.11, numpy 1.26): whole suite=$(PY)" \
	  $(if $(PYTHON313),"Blender 5.2.3 (Python 3.13, numpy 2): whole suite=$(PY52)") \
	  "Blender 4.5 LTS: smoke subset=$(PY45)" "Blender 4.2 LTS: smoke subset=$(PY42)" -- tests

test-core: $(VENV)/.installed
	$(PY) -m pytest tests -m "not blender"

# More than 1,000 random surfaces and parameters through every operator (hypothesis profile "bolus-fuzz";
# `make test` runs about 50 fixed ones); about 15 minutes on 2 busy cores (BOLUS_FUZZ_MAX_FACES=400: 20).
fuzz: $(VENV)/.installed
	BOLUS_FUZZ=1 $(PY) -m pytest tests/test_fuzz_operators.py tests/test_fuzz_core.py -q --hypothesis-show-statistics

# docs/benchmarks.md is written fresh (a header with the date, machine and versions), then every
# script appends its tables; each runs even when an earlier one failed, the target fails if any did.
# `make bench BENCH_ARGS=--quick` passes options to all of them (unfold_bench, shell_bench, learned_print_bench and
# retrieval_bench also take --only NAME).
# The full run takes about 60 minutes on 2 cores (the unfold benchmark 12 of them, the shell one and the retrieval
# from Workbench renders about 11 each, the range scan and the 1M head about 10, the learned print segmentation
# with its training about 2).
BENCH_MD ?= docs/benchmarks.md
BENCH_ARGS ?=
bench: $(VENV)/.installed
	$(PY) bench/benchutil.py --header $(BENCH_MD)
	@rc=0; for b in segment_bench unfold_bench whole_face_bench cuts_bench print_bench learned_print_bench retrieval_bench shell_bench flatten_bench scale_bench rangescan_bench dicom_bench; do \
	  echo "== bench/$$b.py"; $(PY) bench/$$b.py --markdown $(BENCH_MD) $(BENCH_ARGS) || rc=1; \
	done; \
	echo "== bench/rangescan_bench.py --head1m"; $(PY) bench/rangescan_bench.py --head1m --markdown $(BENCH_MD) $(BENCH_ARGS) || rc=1; \
	exit $$rc

extension: $(VENV)/.installed
	mkdir -p dist
	$(PY) -c "import bpy, os, subprocess, sys; cli = os.path.join(bpy.utils.system_resource('SCRIPTS'), 'addons_core', 'bl_pkg', 'cli', 'blender_ext.py'); sys.exit(subprocess.call([sys.executable, cli, 'build', '--source-dir', '.', '--output-dir', 'dist']))"

# ... then installs this machine's zip into every Blender venv present, without the venv's own
# scipy / scikit-learn / manifold3d, and runs segment and unfold through it (scripts/build_extension.py --check).
extension-wheels: $(VENV)/.installed
	$(PY) scripts/build_extension.py --out dist --check $(wildcard $(PY42) $(PY45) $(PY) $(PY52))

house:
	$(or $(wildcard $(PY)),$(PYTHON)) scripts/house.py

operators-doc: $(VENV)/.installed
	$(PY) scripts/operators_doc.py

clean:
	rm -rf out dist build .pytest_cache
