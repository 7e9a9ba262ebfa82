#!/bin/bash
# The committed command reference (docs/commands/) against what the plugins' registry says
# now, and --help-markdown's own behaviour on a directory: stale generated pages removed,
# hand-written files kept, an unwritable target refused with one error line.
# Usage: docs_commands_test.sh BOKEHTOOL SOURCE_DIR WORK_DIR
set -u
tool=$1 src=$2 work=$3
rm -rf "$work" && mkdir -p "$work/fresh"
run() { env -u BOKEH_PLUGIN_PATH "$tool" "$@"; }

if ! run --help-markdown "$work/fresh"; then
    echo "FAIL: bokehtool --help-markdown $work/fresh failed"
    exit 1
fi
if ! diff -r -u "$src/docs/commands" "$work/fresh"; then
    echo "FAIL: docs/commands/ differs from the command registry (diff above: committed vs now)."
    echo "Regenerate it: make docs   (that is: build/bin/bokehtool --help-markdown docs/commands)"
    echo "docs/commands/ holds generated pages only; hand-written text belongs in docs/*.md."
    exit 1
fi

# Printed without a directory: the same pages, one after another.
printed=$(run --help-markdown) || { echo "FAIL: bokehtool --help-markdown (stdout) failed"; exit 1; }
for page in "$work"/fresh/*.md; do
    if ! grep -qF -- "$(sed -n 2p "$page")" <<<"$printed"; then
        echo "FAIL: --help-markdown's printed output lacks $(basename "$page")"
        exit 1
    fi
done

# A second run into a used directory: a stale generated page goes, a hand-written one stays.
mkdir -p "$work/used"
head -1 "$work/fresh/README.md" > "$work/used/gone.md"
echo "# hand-written" > "$work/used/notes.md"
run --help-markdown "$work/used" || { echo "FAIL: second run failed"; exit 1; }
[ ! -e "$work/used/gone.md" ] || { echo "FAIL: a stale generated page was left"; exit 1; }
[ -e "$work/used/notes.md" ] || { echo "FAIL: a hand-written file was removed"; exit 1; }
for page in "$work"/fresh/*.md; do
    cmp -s "$page" "$work/used/$(basename "$page")" || { echo "FAIL: $(basename "$page") differs between runs"; exit 1; }
done

# Bad target: a plain file where the directory should be.
touch "$work/plainfile"
err=$(run --help-markdown "$work/plainfile/sub" 2>&1 >/dev/null); status=$?
if [ $status -ne 1 ] || [ "$(wc -l <<<"$err")" -ne 1 ] || [[ "$err" != "bokehtool ERROR: --help-markdown: "* ]]; then
    echo "FAIL: an unwritable directory gave status $status and: $err"
    exit 1
fi
err=$(run --help-markdown "$work/a" "$work/b" 2>&1 >/dev/null); status=$?
if [ $status -ne 1 ] || [[ "$err" != "bokehtool ERROR: --help-markdown: "* ]] || [ -e "$work/a" ]; then
    echo "FAIL: two directories gave status $status and: $err"
    exit 1
fi
echo "docs/commands/ matches the registry"
