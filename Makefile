# The two set-up commands of the README. Each bootstraps .venv from pyproject.toml on first use.
VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cksum pyproject.toml | cut -d' ' -f1)

.PHONY: run test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/hydrohil serve

# First the kernel is compiled into its cache, each kind of robot in its own process (seconds when
# cached; on a fresh machine the workers would otherwise each compile the same kernel). Then two
# passes: the CPU-bound tests spread over the cores (pytest-xdist, whole files per worker so a
# module's fixtures run once), then the tests marked `realtime` (servers, the browser, Ray) alone,
# so no neighbour's load bends their timing. Both passes always run. A pass that selects nothing
# (PYTEST_ARGS naming one file, say) is fine as long as the other ran something.
TEST_WORKERS ?= auto
test: $(STAMP)
	@$(PY) -m sim_core.precompile --reference || echo "make test: the kernel was not precompiled; the tests compile it"; \
	rc=0; ran=0; \
	$(PY) -m pytest -q -n $(TEST_WORKERS) --maxprocesses=4 --dist loadfile -m "not realtime" $(PYTEST_ARGS); r=$$?; \
	if [ $$r -ne 5 ]; then ran=1; [ $$r -eq 0 ] || rc=$$r; fi; \
	$(PY) -m pytest -q -m realtime $(PYTEST_ARGS); r=$$?; \
	if [ $$r -ne 5 ]; then ran=1; [ $$r -eq 0 ] || rc=$$r; fi; \
	[ $$ran -eq 1 ] || { echo "make test: no test selected"; rc=5; }; \
	exit $$rc

bench: $(STAMP)
	$(VENV)/bin/hydrohil bench

clean:
	rm -rf $(VENV) .pytest_cache artifacts
