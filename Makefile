# Two commands: `make demo` and `make test`. Everything else is a step they call.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Every install takes its versions from constraints.txt, the set the suite last passed with
# (`make lock` refreshes it). torch is pinned by version only, so either build of that version
# satisfies it: PIP_ARGS can point pip at PyTorch's CPU or CUDA wheel index (README).
CONSTRAINTS := constraints.txt
PIP_ARGS ?=
PIP = $(BIN)/pip install --quiet --disable-pip-version-check -c $(CONSTRAINTS) $(PIP_ARGS)
PYTEST_ARGS ?=
# The suite runs in two parts: everything independent across TEST_WORKERS processes (pytest-xdist, a
# module's tests kept together so its fixtures are built once), then the tests marked `serial`, which
# measure time or memory under load, alone. pytest's "no tests" (exit 5) fails the first part; the
# second may find none when PYTEST_ARGS names a file without them.
TEST_WORKERS ?= 2
PYTEST = $(BIN)/python -m pytest
# torch moves only when this is changed on purpose (`make lock TORCH=torch==2.14.1`).
TORCH ?= torch==$(shell sed -n 's/^torch==//p' $(CONSTRAINTS))

.PHONY: demo test test-fast test-durations lint venv venv-test bench lock clean

demo: $(VENV)/.installed
	$(BIN)/illusion-studio demo

test: $(VENV)/.installed-test
	$(BIN)/ruff check .
	$(PYTEST) -n $(TEST_WORKERS) --dist loadfile -m "not serial" $(PYTEST_ARGS)
	$(PYTEST) -p no:xdist -m serial $(PYTEST_ARGS) || [ $$? -eq 5 ]

# The quick loop while coding: no browser, nothing slow, nothing that measures.
test-fast: $(VENV)/.installed-test
	$(PYTEST) -n $(TEST_WORKERS) --dist loadfile -m "not slow and not browser and not serial" $(PYTEST_ARGS)

# Refresh tests/file_durations.json, each test file's seconds: the parallel part hands out the longest
# files first, so that it does not end on one worker running a long file alone. Commit the table.
test-durations: $(VENV)/.installed-test
	$(PYTEST) -n $(TEST_WORKERS) --dist loadfile -m "not serial" --write-file-durations $(PYTEST_ARGS)

lint: $(VENV)/.installed-test
	$(BIN)/ruff check .

bench: $(VENV)/.installed-test
	$(BIN)/illusion-studio bench geometry --json
	$(BIN)/illusion-studio bench prefilter --json
	$(BIN)/illusion-studio bench click --json
	$(BIN)/illusion-studio bench generate --json
	$(BIN)/illusion-studio bench load --json
	$(BIN)/illusion-studio selftest --json

venv: $(VENV)/.installed
venv-test: $(VENV)/.installed-test

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# The demo trains and serves a model, so it needs the model extra (torch) too.
$(VENV)/.installed: pyproject.toml $(CONSTRAINTS) | $(BIN)/python
	$(PIP) -e '.[models]'
	touch $@

$(VENV)/.installed-test: pyproject.toml $(CONSTRAINTS) | $(BIN)/python
	$(PIP) -e '.[test,models]'
	touch $@ $(VENV)/.installed

# Refresh the pinned set: resolve pyproject's ranges afresh in a scratch venv, run the whole
# suite on what was resolved, and only then write constraints.txt (commit it with the change).
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/pip install --quiet --disable-pip-version-check $(PIP_ARGS) "$(TORCH)"
	.venv-lock/bin/pip install --quiet --disable-pip-version-check $(PIP_ARGS) -e '.[test,models]'
	.venv-lock/bin/python -m pytest -q $(PYTEST_ARGS)
	{ echo "# The dependency set the whole suite passed with; every install uses it (pip -c). Refresh: make lock"; \
	  .venv-lock/bin/pip freeze --exclude-editable | sed -E 's/^(torch==[^+]*)\+.*/\1/'; } > $(CONSTRAINTS).new
	mv $(CONSTRAINTS).new $(CONSTRAINTS)
	rm -rf .venv-lock

clean:
	rm -rf $(VENV) var .pytest_cache .hypothesis
