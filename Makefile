# robofmu: every target sets up .venv itself (idempotent), so a fresh clone needs nothing else.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
FMU_SOURCES := $(shell find components -name '*.py' -o -name '*.urdf' -o -name '*.toml') system/packaging/build.py system/packaging/requirements.py \
               $(wildcard system/packaging/fmi_export/*.py system/packaging/fmi_export/*.c system/packaging/fmi_export/*.h)
FMU_STAMP := fmus/.built

.PHONY: venv fmus test check demo bench bench-peers soak clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,arms]'
	touch $(STAMP)

fmus: $(FMU_STAMP)

$(FMU_STAMP): $(STAMP) $(FMU_SOURCES)
	$(VENV)/bin/robofmu build --out fmus
	touch $(FMU_STAMP)

test: $(FMU_STAMP)
	$(PY) -m pytest

# the fast inner loop (a quarter of `make test`'s time or less): lint, then every test but those
# marked slow (2 s or more) or interop (another FMI tool, process or host); `make test` runs all
check: $(STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q -m "not slow and not interop"

demo: $(FMU_STAMP)
	$(VENV)/bin/robofmu demo --out results

bench: $(FMU_STAMP)
	$(PY) benchmarks/run.py
	$(PY) benchmarks/split.py
	$(PY) benchmarks/split.py --experiment 3rrp-circle --steps 300
	$(PY) benchmarks/loop.py
	$(PY) benchmarks/instructions.py
	$(PY) benchmarks/multirate.py
	$(PY) benchmarks/ik.py
	$(PY) benchmarks/arms.py
	$(PY) benchmarks/sweep.py
	$(PY) benchmarks/new_arm.py

# robofmu beside the C++ floor, pydrake and bdsim + Robotics Toolbox on the same loop; each peer
# gets its own environment under benchmarks/peers/ (not project dependencies; a few minutes once)
PEERS := benchmarks/peers
PEER_STAMPS := $(PEERS)/.venv-drake/.installed $(PEERS)/.venv-bdsim/.installed

$(PEERS)/.venv-%/.installed: $(PEERS)/%-requirements.txt
	rm -rf $(PEERS)/.venv-$*
	$(PYTHON) -m venv $(PEERS)/.venv-$*
	$(PEERS)/.venv-$*/bin/pip install --quiet --upgrade pip
	$(PEERS)/.venv-$*/bin/pip install --quiet -r $<
	touch $@

bench-peers: $(FMU_STAMP) $(PEER_STAMPS)
	$(PY) benchmarks/peers.py

# not part of `make test`: 10^6 steps of chess-pd through the master in one process (a few
# minutes); fails if resident memory grows by 5 MB or more after the first tenth
soak: $(FMU_STAMP)
	$(PY) benchmarks/soak.py

clean:
	rm -rf fmus results .pytest_cache
