# layerpilot: `make demo` and `make test` do all set-up on a fresh Debian machine (as root).
SHELL := /bin/bash
APT_PACKAGES := g++ make cmake git python3 python3-venv python3-dev \
  liboctomap-dev libeigen3-dev octomap-tools protobuf-compiler libgtest-dev libbz2-dev \
  libegl1 libegl-mesa0 libgl1-mesa-dri \
  chromium gdal-bin
VENV := .venv
PY := $(VENV)/bin/python
SOURCES := pyproject.toml CMakeLists.txt $(wildcard cpp/*) $(wildcard cpp/*/*) $(wildcard proto/*) $(wildcard config/*/*)
# The editable install maps each Python module to its file: a module added, moved or removed
# changes its folder's time, and the install is redone.
PACKAGE_DIRS := $(shell find python/layerpilot -type d -not -name __pycache__)

.PHONY: demo test cpp-test system build clean

demo: build
	$(VENV)/bin/layerpilot demo

test: build cpp-test
	$(VENV)/bin/lint-imports && $(PY) -m pytest -q -n 2

# The C++ tests (tests/cpp: GoogleTest, run by CTest) in a build of their own, under
# AddressSanitizer and UndefinedBehaviorSanitizer; a failure stops `make test`.
cpp-test: system
	cmake -S . -B build/cpp-tests -DLAYERPILOT_PYTHON=OFF -DLAYERPILOT_TESTS=ON -DLAYERPILOT_SANITIZE=ON -Wno-dev > /dev/null
	cmake --build build/cpp-tests -j2
	ASAN_OPTIONS=detect_leaks=0 ctest --test-dir build/cpp-tests --output-on-failure -j2

build: system $(VENV)/.installed

# Installs only the Debian packages that are missing (so a ready machine needs no root).
system:
	@missing=$$(for p in $(APT_PACKAGES); do dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:" $$missing; \
	  apt-get update -qq && apt-get -o DPkg::Lock::Timeout=120 install -y -qq $$missing; \
	fi

$(VENV)/.installed: $(SOURCES) $(PACKAGE_DIRS)
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

clean:
	rm -rf build $(VENV)
