#!/usr/bin/env python3
"""The library's layers hold: every #include in core/, include/bokeh/, plugins/, tools/ and
python/ runs down the family order of docs/architecture.md, never up or sideways.

* A core family includes only the base and families below it: its own headers, the public
  headers (include/bokeh/) of its family and those below, and the internal headers
  ("family/name.h") of the families below.
* A public header includes only public headers of its family and those below.
* plugins/, tools/, python/ and tests/ use the public headers; they never include a core
  internal header (the plugins' shared option tables live in plugins/shared/).
Prints each include that runs against the order and exits 1; else prints how many it checked."""
import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()

# Lowest first. Each family may include those before it.
ORDER = ["base", "plugin", "io", "metrics", "aperture", "resample", "blur", "optics", "deep", "defocus",
         "truth", "scene", "fit"]
PUBLIC = {
    "base": ["base.h", "parallel.h", "image.h"],
    "plugin": ["plugin.h"],
    "io": ["io.h", "color.h"],
    "metrics": ["metrics.h"],
    "aperture": ["aperture.h"],
    "resample": ["resample.h", "distortion.h"],
    "blur": ["blur.h"],
    "optics": ["lens.h", "optics.h", "spectrum.h", "wave_optics.h"],
    "deep": ["deep.h"],
    "defocus": ["defocus.h"],
    "truth": ["truth.h"],
    "scene": ["scene.h"],
    "fit": ["lens_fit.h"],
}
rank = {f: i for i, f in enumerate(ORDER)}
public_family = {h: f for f, hs in PUBLIC.items() for h in hs}
include = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]', re.M)

problems, checked = [], 0


def check(path, family, text):
    """family: the family `path` belongs to, or None for code outside the library."""
    global checked
    for m in include.finditer(text):
        kind, name = m.group(1), m.group(2)
        line = text.count("\n", 0, m.start()) + 1
        where = f"{path.relative_to(root)}:{line}"
        if name.startswith("bokeh/"):
            checked += 1
            header = name[len("bokeh/"):]
            if header not in public_family:
                problems.append(f"{where}: <{name}> is no public header of a family (add it to the order)")
            elif family is not None and rank[public_family[header]] > rank[family]:
                problems.append(f"{where}: {family} includes <{name}> of {public_family[header]}, a family above it")
        elif kind == '"' and "/" in name and name.split("/")[0] in rank:
            checked += 1
            owner = name.split("/")[0]
            if family is None:
                problems.append(f"{where}: includes the library's internal header \"{name}\"; use the public headers")
            elif rank[owner] > rank[family]:
                problems.append(f"{where}: {family} includes \"{name}\" of {owner}, a family above it")
        elif kind == '"' and family is not None and path.is_relative_to(root / "core"):
            checked += 1
            problems.append(f"{where}: \"{name}\": name a core header by its family's folder (\"family/{name}\")")


for path in sorted((root / "core").rglob("*")):
    if path.suffix not in (".cpp", ".h"):
        continue
    family = path.relative_to(root / "core").parts[0]
    if family not in rank:
        problems.append(f"{path.relative_to(root)}: core/{family}/ is not a family of the order")
        continue
    check(path, family, path.read_text(encoding="utf-8"))
for path in sorted((root / "include" / "bokeh").glob("*.h")):
    family = public_family.get(path.name)
    if family is None:
        problems.append(f"{path.relative_to(root)}: a public header no family owns")
        continue
    check(path, family, path.read_text(encoding="utf-8"))
for top in ("plugins", "tools", "python", "tests"):
    for path in sorted((root / top).rglob("*")):
        if path.suffix in (".cpp", ".h") and "build" not in path.parts:
            check(path, None, path.read_text(encoding="utf-8"))

for p in problems:
    print(p)
print(f"{checked} includes checked, {len(problems)} against the order")
sys.exit(1 if problems else 0)
