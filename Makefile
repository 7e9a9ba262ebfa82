# The commands a newcomer types. Each one installs what is missing, configures, builds.
#   make demo   install what bokehtool needs, build it, render the built-in scene:
#               out/demo.exr + out/demo.png (no tests, benches or bindings are built)
#   make test   install everything, build everything, run every test (ctest)
#   make bench  run the speed/accuracy benchmarks
#   make docs   regenerate the command reference docs/commands/ from the plugins
#   make test-asan  the tests built with AddressSanitizer + UndefinedBehaviorSanitizer
#   make fuzz   build the libFuzzer targets (clang-14) and run each for FUZZ_SECONDS
BUILD ?= build
JOBS  ?= 2
BOKEHTOOL = $(BUILD)/bin/bokehtool

.PHONY: all deps deps-tool configure build tool demo test test-asan fuzz bench docs micro install clean

all: build

deps:
	@tools/install-deps.sh

deps-tool:
	@tools/install-deps.sh tool

# Configured once; options already in the cache are kept (the test build turns the tests on).
$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release

configure: $(BUILD)/CMakeCache.txt

# Everything: library, tool, plugins, tests, bench harness, Python module.
build: deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DBOKEH_BUILD_TESTS=ON -DBOKEH_BUILD_PYTHON=ON
	cmake --build $(BUILD) -j $(JOBS) --target all bokeh-bench

# bokehtool and its plugins alone.
tool: deps-tool
	@$(MAKE) --no-print-directory configure
	cmake --build $(BUILD) -j $(JOBS) --target tool

demo: tool
	@mkdir -p out
	$(BOKEHTOOL) -v --scene lights -o out/sharp.exr --defocus:focus=6:fstop=2 -o out/demo.exr --ch R,G,B -o out/demo.png
	$(BOKEHTOOL) out/sharp.exr --defocus:focus=6:fstop=2:output=focalplane -o out/focalplane.png
	$(BOKEHTOOL) -v out/sharp.exr --defocus:focus=6:fstop=2:lens=achromat:diffraction=exact:onion=0.15 --ch R,G,B -o out/demo_lens.png
	$(BOKEHTOOL) --bokeh:lens=achromat:fstop=1.4:diffraction=exact:onion=0.15:catseye=0.5:lateralr=0.002:lateralb=-0.002:sheet=1 60 -o out/bokeh_sheet.png
	$(BOKEHTOOL) out/sharp.exr --defocus:focus=6:fstop=2:lens=achromat:catseye=0.5 --lensdistort:k1=-0.06:k2=0.01:lateralr=0.002:lateralb=-0.002 --ch R,G,B -o out/demo_field.png
	$(BOKEHTOOL) out/sharp.exr --defocus:focus=2.5:fstop=1.4:kernel=polygon:blades=7:rotation=12:curvature=0.15:lens=uncorrected:correction=0:monochromatic=0.5:chromatic=0.8 -o out/plate.exr
	@echo "demo: the plate's lens: kernel=polygon:blades=7:rotation=12:curvature=0.15:lens=uncorrected:correction=0:monochromatic=0.5:chromatic=0.8"
	$(BOKEHTOOL) out/plate.exr --fitlens:at=575,187/1548,498/1850,588:box=96:fstop=1.4 --ch R,G,B -o out/demo_fit.png
	@echo "demo: wrote out/sharp.exr (the scene, RGBA+Z), out/demo.exr + out/demo.png (its depth of field), out/demo_lens.png (the same with an achromat's lens character on the highlights), out/focalplane.png, out/bokeh_sheet.png (an achromat's bokeh across defocus and field, with cat's eye and lateral colour), out/demo_field.png (the lens across the field: cat's eye, barrel distortion, lateral colour), out/plate.exr and out/demo_fit.png (the lens fitted back from three of the plate's highlights: crop, fit, difference x 4, fitted light)"

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

# The test suite with ASan + UBSan (g++, build-asan/). Only our code is instrumented
# (Debian's OIIO and OpenEXR are not). Leak checking is off: OIIO and OCIO keep caches
# alive until exit. Left out: installed_package (builds against an installed,
# uninstrumented package), bench_smoke (timings) and python_module (an instrumented module
# cannot load into Debian's uninstrumented python3: "ASan runtime does not come first");
# no fuzz targets (clang's ASan runtime cannot share a process with g++'s). Compiled file by
# file (no unity batches), so a file that leans on its batch neighbours' includes fails here.
# docs/robustness.md has its cost.
ASAN_BUILD ?= build-asan
SANITIZE = -fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer
test-asan: deps
	cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBOKEH_FUZZ=OFF -DBOKEH_UNITY_BUILD=OFF \
	  -DCMAKE_CXX_FLAGS="$(SANITIZE)" -DCMAKE_C_FLAGS="$(SANITIZE)" \
	  -DCMAKE_EXE_LINKER_FLAGS="$(SANITIZE)" -DCMAKE_SHARED_LINKER_FLAGS="$(SANITIZE)" \
	  -DCMAKE_MODULE_LINKER_FLAGS="$(SANITIZE)"
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=detect_leaks=0:abort_on_error=0 \
	  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --output-on-failure -j $(JOBS) -E '^(installed_package|bench_smoke|python_module)$$'

# libFuzzer (clang-14): the targets of tests/fuzz, built with the project when clang++-14
# and its fuzzer runtime are there ($(BUILD)/bin/fuzz_*), each run for FUZZ_SECONDS from
# the committed corpus and past findings (replayed first); new inputs and findings land in
# $(FUZZ_WORK). docs/robustness.md has the targets and what they check.
FUZZ_TARGETS ?= read_image command_line kernel_image deep
FUZZ_SECONDS ?= 60
FUZZ_WORK    ?= build-fuzz
fuzz: deps
	@command -v clang++-14 >/dev/null || { echo "make fuzz: needs clang++-14 and libclang-rt-14-dev (apt-get install clang-14 libclang-rt-14-dev)"; exit 1; }
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DBOKEH_FUZZ=ON
	cmake --build $(BUILD) -j $(JOBS)
	/usr/bin/python3 tests/fuzz/make_seeds.py $(FUZZ_WORK)/seeds_read_image
	FUZZ_LEDGER=$(CURDIR)/tests/fuzz/runs.csv tests/fuzz/run_fuzz.sh $(BUILD)/bin $(FUZZ_WORK) $(FUZZ_SECONDS) $(FUZZ_TARGETS); \
	  status=$$?; /usr/bin/python3 tests/fuzz/ledger.py tests/fuzz/runs.csv docs/robustness.md; exit $$status

# ../shared/data: test images kept beside the repository; without it the defocus task
# measures the built-in scenes only and the deep task is skipped, saying so.
bench: build
	@mkdir -p docs/bench
	$(BUILD)/bin/bokeh-bench --threads 2 --reps 5 --csv docs/bench/blur.csv
	$(BUILD)/bin/bokeh-bench --task defocus --threads 2 --reps 5 --data ../shared/data --images docs/bench --csv docs/bench/defocus.csv
	$(BUILD)/bin/bokeh-bench --task resample --threads 2 --reps 5 --images docs/bench --csv docs/bench/resample.csv
	$(BUILD)/bin/bokeh-bench --task iris --threads 2 --csv docs/bench/iris.csv
	$(BUILD)/bin/bokeh-bench --task deep --threads 2 --reps 5 --data ../shared/data --images docs/bench --csv docs/bench/deep.csv
	$(BUILD)/bin/bokeh-bench --task diffraction --reps 3 --csv docs/bench/diffraction.csv
	$(BUILD)/bin/bokeh-bench --task plans --threads 2 --reps 3 --data ../shared/data --csv docs/bench/plans.csv
	/usr/bin/python3 tools/bokeh-bench/chart.py docs/bench/blur.csv docs/bench
	/usr/bin/python3 tools/bokeh-bench/chart.py docs/bench/defocus.csv docs/bench
	/usr/bin/python3 tools/bokeh-bench/chart.py docs/bench/deep.csv docs/bench
	/usr/bin/python3 tools/bokeh-bench/diffraction_chart.py docs/bench/diffraction.csv docs/bench
	/usr/bin/python3 tools/bokeh-bench/plans_chart.py docs/bench/plans.csv docs/bench
	/usr/bin/python3 tools/bokeh-bench/chart.py docs/bench/resample.csv docs/bench --size-label "reduction factor" && /usr/bin/python3 tools/bokeh-bench/artifact_chart.py docs/bench/resample_artifacts.csv docs/bench --timings docs/bench/resample.csv
	/usr/bin/python3 tools/bokeh-bench/tables.py docs/benchmarks.md docs/bench

# The command reference, one page per plugin module, from the registry (the ctest
# docs_commands_current fails while the committed pages differ).
docs: build
	env -u BOKEH_PLUGIN_PATH $(BOKEHTOOL) --help-markdown docs/commands

# The microbenchmarks behind the exact methods' cost models (Google Benchmark), the
# methods' repetitions interleaved so the machine's drift falls on all of them alike.
micro: build
	cmake --build $(BUILD) -j $(JOBS) --target bokeh-micro
	$(BUILD)/bin/bokeh-micro --benchmark_repetitions=3 --benchmark_enable_random_interleaving=true \
	  --benchmark_report_aggregates_only=true

install: build
	cmake --install $(BUILD) --prefix $(or $(PREFIX),/usr/local)

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(FUZZ_WORK) out
