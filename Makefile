# The commands a newcomer types. Each one installs what is missing, configures, builds.
#   make demo   render the built-in scene and write out/demo.exr + out/demo.png
#   make test   build and run every test (ctest)
#   make bench  run the speed/accuracy benchmarks
BUILD ?= build
JOBS  ?= 2
BOKEHTOOL = $(BUILD)/bin/bokehtool

.PHONY: all deps configure build demo test bench install clean

all: build

deps:
	@tools/install-deps.sh

$(BUILD)/CMakeCache.txt: | deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release

configure: $(BUILD)/CMakeCache.txt

build: deps configure
	cmake --build $(BUILD) -j $(JOBS)

demo: build
	@mkdir -p out
	$(BOKEHTOOL) -v --scene lights -o out/demo.exr --ch R,G,B -o out/demo.png
	@echo "demo: wrote out/demo.exr (RGBA+Z, float) and out/demo.png (sRGB preview)"

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: build
	@mkdir -p docs/bench
	$(BUILD)/bin/bokeh-bench --threads 2 --reps 5 --csv docs/bench/blur.csv
	/usr/bin/python3 tools/bokeh-bench/chart.py docs/bench/blur.csv docs/bench

install: build
	cmake --install $(BUILD) --prefix $(or $(PREFIX),/usr/local)

clean:
	rm -rf $(BUILD) out
