# make demo  - run the main job on the built-in example and write out/
# make test  - the whole test suite (core, Blender 5.0 and a Blender 4.2 LTS smoke subset)
# make bench - benchmarks (printed, not asserted)
# make extension - the installable extension zip in dist/ (Blender's own builder, from bpy)
# make extension-wheels - one zip per platform in dist/, with scipy and scikit-learn inside
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
VENV42 := .venv42
BPY_LTS := 4.2.0
PY     := $(VENV)/bin/python
PY42   := $(VENV42)/bin/python

.PHONY: demo test test-core bench extension extension-wheels clean

$(VENV)/.installed: requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	touch $@

$(VENV42)/.installed: requirements.txt
	test -x $(PY42) || $(PYTHON) -m venv $(VENV42)
	grep -v '^bpy==' requirements.txt > $(VENV42)/requirements-lts.txt
	$(PY42) -m pip install --quiet --disable-pip-version-check -r $(VENV42)/requirements-lts.txt bpy==$(BPY_LTS)
	touch $@

demo: $(VENV)/.installed
	$(PY) scripts/demo.py --out out

test: $(VENV)/.installed $(VENV42)/.installed
	$(PY) -m pytest tests
	$(PY42) -m pytest tests -m smoke

test-core: $(VENV)/.installed
	$(PY) -m pytest tests -m "not blender"

bench: $(VENV)/.installed
	$(PY) bench/segment_bench.py
	$(PY) bench/unfold_bench.py
	$(PY) bench/cuts_bench.py
	$(PY) bench/print_bench.py

extension: $(VENV)/.installed
	mkdir -p dist
	$(PY) -c "import bpy, os, subprocess, sys; cli = os.path.join(bpy.utils.system_resource('SCRIPTS'), 'addons_core', 'bl_pkg', 'cli', 'blender_ext.py'); sys.exit(subprocess.call([sys.executable, cli, 'build', '--source-dir', '.', '--output-dir', 'dist']))"

extension-wheels: $(VENV)/.installed
	$(PY) scripts/build_extension.py --out dist

clean:
	rm -rf out dist build .pytest_cache
