#!/usr/bin/env python3
"""Every relative link in the project's Markdown resolves: the file exists, and an anchor
(#section) names a heading of that page (GitHub's slugs: lower case, punctuation dropped,
spaces to hyphens). Links to web pages are not followed. Prints each broken link and exits
1; else prints how many links it checked."""
import pathlib
import re
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".").resolve()
pages = [p for p in root.rglob("*.md")
         if not any(part in ("build", "build-asan", "build-fuzz", "out", ".git") or part.startswith("build")
                    for part in p.relative_to(root).parts)]

link = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)|!\[[^\]]*\]\(([^)\s]+)\)")
fence = re.compile(r"^(```|~~~)")


def slug(heading):
    s = heading.strip().lower()
    s = re.sub(r"[`*_]", "", s)
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(page):
    seen, out = {}, set()
    in_code = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if fence.match(line):
            in_code = not in_code
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m and not in_code:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


broken, checked = [], 0
for page in sorted(pages):
    in_code = False
    for lineno, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if fence.match(line):
            in_code = not in_code
            continue
        if in_code:
            continue
        for m in link.finditer(re.sub(r"`[^`]*`", "", line)):
            target = m.group(1) or m.group(2)
            if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
                continue
            checked += 1
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            where = f"{page.relative_to(root)}:{lineno}: {target}"
            if not dest.exists():
                broken.append(f"{where}: no such file")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{where}: no heading '#{anchor}' in {dest.relative_to(root)}")

for b in broken:
    print("broken link:", b)
print(f"docs links: {checked} checked in {len(pages)} pages, {len(broken)} broken")
sys.exit(1 if broken else 0)
