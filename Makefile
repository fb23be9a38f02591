# planeslam: the two README commands.
#   make run    install what is missing, build (Release, -j2), run SLAM on the built-in scene
#   make test   install what is missing, build, run the whole test suite
# Both start from a fresh Debian 12 machine; Debian packages are installed only when missing.

BUILD_DIR ?= build
JOBS ?= 2
CMAKE_ARGS ?=
RUN_ARGS ?=

# Debian 12 packages the build needs (PCL without recommends: about a minute instead of many);
# pybind11, numpy, pytest: the Python module; parallel, slurm-wlm, munge: planeslam batch.
DEB_PACKAGES := build-essential cmake ccache pkg-config libeigen3-dev libceres-dev liboctomap-dev \
  libpcl-dev libabsl-dev libyaml-cpp-dev libgtest-dev libgmock-dev libcli11-dev libpng-dev zlib1g-dev libdeflate-dev \
  nlohmann-json3-dev clang libclang-rt-14-dev python3 \
  pybind11-dev python3-dev python3-numpy python3-pytest \
  parallel slurm-wlm munge nodejs chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

SAN_BUILD_DIR ?= build-asan
FUZZ_SECONDS ?= 30

.PHONY: deps configure build run test sanitize fuzz ci clean

deps:
	@missing=$$(for p in $(DEB_PACKAGES); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null \
	  | grep -q 'install ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing missing Debian packages:" $$missing; \
	  $(SUDO) apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q --no-install-recommends $$missing; \
	fi
	@# Debian's nodejs comes without npm (NodeSource's includes it and conflicts with Debian's npm).
	@command -v npm >/dev/null || { $(SUDO) apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q --no-install-recommends npm; }
	@$(MAKE) --no-print-directory web/node_modules/.package-lock.json

# The report's pinned web packages (three.js, inlined into report.html; esbuild; playwright-core for
# the browser test), reinstalled when package-lock.json is newer than the installed tree.
web/node_modules/.package-lock.json: web/package-lock.json
	npm ci --prefix web --no-audit --no-fund

configure: deps
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release $(CMAKE_ARGS)

build: configure
	cmake --build $(BUILD_DIR) -j$(JOBS)

run: build
	./$(BUILD_DIR)/bin/planeslam run $(RUN_ARGS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j$(JOBS)

# The whole test suite under AddressSanitizer + UndefinedBehaviorSanitizer (clang; PCL baselines
# off to keep the build short). The same build carries the libFuzzer targets.
sanitize: deps
	CC=clang CXX=clang++ cmake -S . -B $(SAN_BUILD_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DPLANESLAM_SANITIZERS="address;undefined" -DPLANESLAM_WITH_PCL=OFF -DPLANESLAM_BUILD_FUZZERS=ON \
	  -DPLANESLAM_BUILD_PYTHON=OFF
	cmake --build $(SAN_BUILD_DIR) -j$(JOBS)
	cd $(SAN_BUILD_DIR) && ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  ctest --output-on-failure -j$(JOBS)

# Bounded fuzzing of every parser ($(FUZZ_SECONDS) s each); fails on any crash, hang or report.
fuzz: sanitize
	./tests/fuzz/run_fuzzers.sh $(SAN_BUILD_DIR)/bin $(FUZZ_SECONDS)

# What CI runs: the README test command, then the sanitizer suite and the fuzzers.
ci: test fuzz

clean:
	rm -rf $(BUILD_DIR) $(SAN_BUILD_DIR)

# Re-measures the figures of docs/RESULTS.md into results_out/ (3 to 6 minutes on 2 cores).
.PHONY: results
results: build
	./docs/measure_results.sh $(BUILD_DIR)/bin/planeslam
