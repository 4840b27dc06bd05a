# Two commands on a fresh clone:  `make demo` (set up + main job)  and  `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
DATA   ?= data
DEMO_SCENES ?= 10
DEMO_SIZE   ?= 3840x2160

.PHONY: setup demo test test-all requirements bench lint clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade "pip>=24"
	$(VENV)/bin/pip install -q -c constraints.txt -e ".[dev,pdf,distributed]"
	touch $@

## The main job on the embedded default: synthetic test scenes -> preview.
demo: setup
	$(PY) -m assurance synth --out $(DATA)/test --split test --scenes $(DEMO_SCENES) --size $(DEMO_SIZE) --jobs 2
	$(PY) -m assurance preview --data $(DATA)/test --count 3 --out reports/preview.png
	@echo "Preview written to reports/preview.png"

## The test suite (fast; long campaigns and training are marked slow and excluded).
test: setup
	$(PY) -m pytest -q -m "not slow"

test-all: setup
	$(PY) -m pytest -q

requirements: setup
	$(PY) -m pytest -q -m requirements

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

lint: setup
	$(VENV)/bin/ruff check el assurance tests benchmarks

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
