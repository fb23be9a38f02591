# planeslam: the two README commands.
#   make run    install what is missing, build (Release, -j2), run SLAM on the built-in scene
#   make test   install what is missing, build, run the whole test suite
# Both start from a fresh Debian 12 machine; Debian packages are installed only when missing.

BUILD_DIR ?= build
JOBS ?= 2
CMAKE_ARGS ?=
RUN_ARGS ?=

# Debian 12 packages the build needs (PCL without recommends: about a minute instead of many).
DEB_PACKAGES := build-essential cmake ccache pkg-config libeigen3-dev libceres-dev liboctomap-dev \
  libpcl-dev libyaml-cpp-dev libgtest-dev libgmock-dev libcli11-dev libpng-dev zlib1g-dev \
  nlohmann-json3-dev clang libclang-rt-14-dev
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: deps configure build run test clean

deps:
	@missing=$$(for p in $(DEB_PACKAGES); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null \
	  | grep -q 'install ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing missing Debian packages:" $$missing; \
	  $(SUDO) apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q --no-install-recommends $$missing; \
	fi

configure: deps
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release $(CMAKE_ARGS)

build: configure
	cmake --build $(BUILD_DIR) -j$(JOBS)

run: build
	./$(BUILD_DIR)/bin/planeslam run $(RUN_ARGS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j$(JOBS)

clean:
	rm -rf $(BUILD_DIR)
