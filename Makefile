# spar-py: `make demo` plans the paper's peg-and-block cell; `make test` runs every test.
# Both set everything up first (scripts/setup.sh), on a fresh machine too.
VENV   := .venv
PY     := $(VENV)/bin/python
SPAR   := $(VENV)/bin/spar
PROBLEM ?= kb/problems/peg_in_block.yaml

.PHONY: setup demo test test-python test-prolog bench regress lint fuzz fuzz-full clean

setup:
	@scripts/setup.sh

demo: setup
	$(SPAR) plan $(PROBLEM) --dot docs/demo --png docs/demo

# pytest on every core (pytest-xdist, each file on one worker): tests/conftest.py starts the
# heavy files first; the plunit suites run as one of the tests (tests/test_plunit.py). `make test PYTEST_ARGS="-m 'not slow'"` skips the
# slow ones; TEST_WORKERS=0 runs everything in one process.
TEST_WORKERS ?= auto
PYTEST_ARGS ?=
test: setup
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS)

bench: setup
	$(PY) -m pip install -q -e '.[bench]' 2>&1 | grep -v '^WARNING: Location' || true
	$(PY) -m bench

regress: setup
	$(SPAR) regress kb/problems

# kbfuzz (tests/fuzz/README.md): `make fuzz` mutates the paper's cell files (the sample that
# `make test` runs); `make fuzz-full` every kb file, 200 mutants each (about 30 min on 2 cores)
fuzz: setup
	$(PY) -m tests.fuzz.kbfuzz --paper --seed 13 --count 50 --timeout 3 --jobs 2

fuzz-full: setup
	SPAR_FUZZ_FULL=1 $(PY) -m pytest -m fuzz_full tests/test_fuzz.py

lint: setup
	$(VENV)/bin/ruff check src tests bench

clean:
	rm -rf $(VENV) src/spar_py/_swipl.json .pytest_cache .hypothesis
