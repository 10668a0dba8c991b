# robofmu: every target sets up .venv itself (idempotent), so a fresh clone needs nothing else.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
FMU_SOURCES := $(shell find components -name '*.py' -o -name '*.urdf' -o -name '*.toml') system/build.py \
               $(wildcard system/fmi_export/*.py system/fmi_export/*.c)
FMU_STAMP := fmus/.built

.PHONY: venv fmus test demo bench soak clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

fmus: $(FMU_STAMP)

$(FMU_STAMP): $(STAMP) $(FMU_SOURCES)
	$(VENV)/bin/robofmu build --out fmus
	touch $(FMU_STAMP)

test: $(FMU_STAMP)
	$(PY) -m pytest

demo: $(FMU_STAMP)
	$(VENV)/bin/robofmu demo --out results

bench: $(FMU_STAMP)
	$(PY) benchmarks/run.py
	$(PY) benchmarks/split.py
	$(PY) benchmarks/loop.py
	$(PY) benchmarks/ik.py
	$(PY) benchmarks/sweep.py

# not part of `make test`: 10^6 steps of chess-pd through the master in one process (a few
# minutes); fails if resident memory grows by 5 MB or more after the first tenth
soak: $(FMU_STAMP)
	$(PY) benchmarks/soak.py

clean:
	rm -rf fmus results .pytest_cache
