# Two commands on a fresh machine (Python 3.11): `make reproduce` and `make test`.
# Each creates .venv from environment.txt first when it is missing or out of date.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
ARGS ?=

.PHONY: reproduce test bench lab clean

# the package itself is installed editable: `python -m dynslam_lite` and `import dynslam_lite`
# work from any folder, and notebooks opened in JupyterLab find it
$(VENV)/.installed: environment.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment.txt
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $@

reproduce: $(VENV)/.installed  ## batch reproduction on the embedded synthetic default -> reports/
	$(PY) -m dynslam_lite reproduce $(ARGS)

test: $(VENV)/.installed  ## the test suite
	$(PY) -m pytest -q $(ARGS)

bench: $(VENV)/.installed  ## speed and memory figures (ms/frame per stage, peak memory)
	$(PY) -m dynslam_lite bench $(ARGS)

lab: $(VENV)/.installed  ## JupyterLab on the notebooks (and reports/executed/) with the project's environment
	$(VENV)/bin/jupyter lab --ServerApp.root_dir=$(CURDIR) $(ARGS) notebooks/README.md

clean:
	rm -rf build .pytest_cache
