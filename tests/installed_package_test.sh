#!/usr/bin/env bash
# Install OpenBokeh into a scratch prefix, then, outside the source tree, build the C++
# example and a third-party plugin against the installed package (find_package) and
# run both through the installed bokehtool.
#   installed_package_test.sh BUILD_DIR SOURCE_DIR SCRATCH_DIR
set -euo pipefail
build=$1 src=$2 scratch=$3
prefix=$scratch/prefix
rm -rf "$scratch" && mkdir -p "$scratch"

cmake --install "$build" --prefix "$prefix" >/dev/null

cmake -S "$src/examples/cpp_consumer" -B "$scratch/example" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$scratch/example" -j 2 >/dev/null
"$scratch/example/make_scene" "$scratch/scene.exr" 64 32

cmake -S "$src/tests/thirdparty_plugin" -B "$scratch/plugin" -DCMAKE_PREFIX_PATH="$prefix" \
      -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$scratch/plugin" -j 2 >/dev/null

tool=$prefix/bin/bokehtool
export BOKEH_PLUGIN_PATH=$scratch/plugin
"$tool" --plugins | grep -q "loaded $scratch/plugin/invert.so: --invert"
"$tool" --help --invert | grep -q "third-party example"
"$tool" "$scratch/scene.exr" --invert:gain=2 -o "$scratch/inverted.exr"
# The installed tool found its own plugins and OCIO config, and the plugin ran:
# R + inverted R = gain everywhere.
"$tool" "$scratch/scene.exr" --info -v | grep -q "bokeh:scene"
python3 - "$scratch/scene.exr" "$scratch/inverted.exr" <<'PY'
import subprocess, sys
def first_pixel(path):
    out = subprocess.run(["oiiotool", path, "--ch", "R", "--cut", "1x1+10+10", "--printstats"],
                         capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        if "Stats Avg:" in line:
            return float(line.split()[2])
    raise SystemExit("no stats from oiiotool for " + path)
a, b = first_pixel(sys.argv[1]), first_pixel(sys.argv[2])
if abs(a + b - 2.0) > 1e-5:
    raise SystemExit(f"--invert:gain=2 gave {b} for {a}")
PY
# The Python module, when it was built: imported from the install tree, it finds the
# installed library, plugins and OCIO config (not the build tree's) and runs.
module=$(ls "$prefix"/lib/python3*/dist-packages/openbokeh*.so 2>/dev/null | head -1 || true)
if [[ -n "$module" ]]; then
    PYTHONPATH=$(dirname "$module") /usr/bin/python3 - "$prefix" <<'PY'
import sys
import openbokeh
prefix = sys.argv[1]
if not openbokeh.plugin_dir.startswith(prefix + "/"):
    raise SystemExit(f"the installed module loads its plugins from {openbokeh.plugin_dir}")
img = openbokeh.to_array(openbokeh.scene("lights", width=64, height=36))
out, report = openbokeh.defocus(img, focus=6, fstop=2)
if out.shape != (36, 64, 4) or report.method != "layers":
    raise SystemExit(f"the installed module's defocus gave {out.shape}, {report.method}")
PY
    echo "installed package: Python module OK ($module)"
fi
echo "installed package: example and third-party plugin OK"
