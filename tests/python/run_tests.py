#!/usr/bin/env python3
"""Run the Python module's tests with pytest, for ctest (tests/CMakeLists.txt).

Exits 77 (ctest: skipped), saying why, when numpy, pytest or OpenImageIO's Python module
cannot be imported by this interpreter, or when the module was not built.
    run_tests.py [--not-built REASON] [pytest arguments...]
"""
import os
import sys

if len(sys.argv) > 2 and sys.argv[1] == "--not-built":
    print(f"SKIPPED: the openbokeh module was not built: {sys.argv[2]}")
    sys.exit(77)

missing = []
for module, package in (("numpy", "python3-numpy"), ("pytest", "python3-pytest"),
                        ("OpenImageIO", "python3-openimageio")):
    try:
        __import__(module)
    except ImportError as e:
        missing.append(f"{module} ({package}): {e}")
if missing:
    print(f"SKIPPED: {sys.executable} cannot import " + "; ".join(missing))
    sys.exit(77)

import pytest  # noqa: E402

here = os.path.dirname(os.path.abspath(__file__))
sys.exit(pytest.main(["-q", "-rs", "-p", "no:cacheprovider", here] + sys.argv[1:]))
