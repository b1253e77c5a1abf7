# OCSLAM: every target creates what it needs itself (virtual environment, packages, browser).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip
OCSLAM := $(VENV)/bin/ocslam
HOST ?= 127.0.0.1
PORT ?= 8080
ARGS ?=
PYTEST_ARGS ?=

.PHONY: setup run test test-fast bench train browser strace egl lint clean help

help:
	@echo "make run    set up .venv and start the web app on http://$(HOST):$(PORT)"
	@echo "make test   set up .venv (+ test extras, chromium), run make lint and the whole suite"
	@echo "make lint   ruff on app/ tests/ scripts/, mypy on app/ocslam"
	@echo "make bench  run every benchmark and print the tables"
	@echo "make train  install the [train] extra and train the detector (about an hour)"

$(PY):
	$(PYTHON) -m venv $(VENV)

# Re-install when the project's metadata changes.
$(VENV)/.installed: pyproject.toml | $(PY)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet -e .
	@touch $@

$(VENV)/.installed-test: pyproject.toml $(VENV)/.installed
	$(PIP) install --quiet -e ".[test,scale]"
	@touch $@

setup: $(VENV)/.installed egl

run: setup
	@echo "OCSLAM: open http://$(HOST):$(PORT) in your browser (Ctrl-C stops)"
	$(OCSLAM) run --host $(HOST) --port $(PORT) $(ARGS)

# Debian's chromium for the browser test (playwright install cannot download browsers here).
browser:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then \
	  true; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing Debian's chromium for the browser tests"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	    || echo "WARNING: apt-get install chromium failed; browser tests will be skipped"; \
	else \
	  echo "NOTE: chromium is not installed and this is not root: run 'sudo apt-get install chromium'"; \
	  echo "      (or set OCSLAM_CHROMIUM=/path/to/chromium); the browser tests will be skipped."; \
	fi

# Debian's strace for the no-outbound-traffic test (tests/test_bad_inputs_server.py; skipped without it).
strace:
	@if command -v strace >/dev/null 2>&1; then \
	  true; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing Debian's strace for the no-outbound-traffic test"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq strace >/dev/null) \
	    || echo "WARNING: apt-get install strace failed; the no-outbound-traffic test will be skipped"; \
	else \
	  echo "NOTE: strace is not installed and this is not root: run 'sudo apt-get install strace'"; \
	  echo "      (the no-outbound-traffic test will be skipped)."; \
	fi

# Mesa's EGL + llvmpipe for pybullet's EGL renderer plugin (the camera renders faster than with
# TinyRenderer, no GPU or display needed); without them the app falls back to TinyRenderer.
EGL_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri
egl:
	@if ldconfig -p 2>/dev/null | grep -q libEGL_mesa.so.0; then \
	  true; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "installing Mesa's EGL for the camera renderer ($(EGL_PACKAGES))"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(EGL_PACKAGES) >/dev/null) \
	    || echo "WARNING: apt-get install $(EGL_PACKAGES) failed; the camera will use TinyRenderer"; \
	else \
	  echo "NOTE: Mesa's EGL is not installed and this is not root: run 'sudo apt-get install $(EGL_PACKAGES)'"; \
	  echo "      (the camera falls back to pybullet's slower TinyRenderer without it)."; \
	fi

# A hard cap on the whole suite (normally 9-10 min on 2 cores): a test wedged inside C code that holds
# the GIL defeats pytest-timeout's signal; faulthandler_timeout (pyproject) has printed every thread's
# stack by then, so the run fails with where it hung instead of running into CI's 90-minute limit.
TEST_TIME_LIMIT ?= 2700
test: $(VENV)/.installed-test browser strace egl lint
	timeout -k 30 $(TEST_TIME_LIMIT) $(PY) -m pytest $(PYTEST_ARGS)

test-fast: $(VENV)/.installed-test egl
	$(PY) -m pytest -m "not slow and not browser" $(PYTEST_ARGS)

bench: setup
	$(OCSLAM) bench all $(ARGS)

train: setup
	$(PIP) install --quiet -e ".[train]"
	$(OCSLAM) train-detector $(ARGS)

# Style and types: ruff on everything, mypy on the pure core (both pinned in the [test] extra).
lint: $(VENV)/.installed-test
	$(VENV)/bin/ruff check app tests scripts
	$(VENV)/bin/mypy app/ocslam

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
