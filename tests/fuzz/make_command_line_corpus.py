#!/usr/bin/python3
"""Seeds and a dictionary for the command-line fuzz target, from the registry itself
(`bokehtool --help`): every command with every option at its default and its arguments
filled in, the frame-sequence forms, and the dictionary of command names, option names
and choice words. Arguments in a seed are separated by NUL bytes, as the target reads
them.
Usage: make_command_line_corpus.py BOKEHTOOL CORPUS_DIR DICT_FILE"""
import hashlib
import os
import re
import subprocess
import sys

ARG_VALUES = {"WxH": "9x7", "N": "2", "NAME": "lights", "FILE": "in.exr", "SPEC": "1-3",
              "SECONDS": "30", "SIZE": "512M", "TYPE": "half", "CHANNELS": "R,G,B,A",
              "VALUE": "1", "FROM": "scene_linear", "TO": "srgb", "SPACE": "srgb",
              "NEAR": "1", "FAR": "2.5"}


def main():
    tool, corpus, dict_path = sys.argv[1:4]
    text = subprocess.run([tool, "--help"], capture_output=True, text=True, check=True,
                          env={k: v for k, v in os.environ.items() if k != "BOKEH_PLUGIN_PATH"}).stdout
    commands = []  # (name, [arg names], [(option, default, choices)])
    for line in text.splitlines():
        m = re.match(r"^  (-{1,2}[a-z-]+)(?: ([A-Z][A-Zx ]*?))?\s{2,}", line)
        if m:
            commands.append((m.group(1), (m.group(2) or "").split(), []))
            continue
        m = re.match(r"^      :([a-z_]+)=(\S*)\s+\((.*?)\)", line)
        if m and commands:
            choices = m.group(3)[7:].split("|") if m.group(3).startswith("one of ") else []
            commands[-1][2].append((m.group(1), m.group(2), choices))
    if not commands:
        sys.exit("make_command_line_corpus: no commands in bokehtool --help")

    lines = []
    for name, args, options in commands:
        filled = [ARG_VALUES.get(a, "1") for a in args]
        lines.append(["a.exr", "b.exr", name] + filled + ["-o", "out.exr"])
        if options:
            mods = ":".join(f"{o}={d}" for o, d, _ in options)
            lines.append(["a.exr", "b.exr", f"{name}:{mods}"] + filled + ["-o", "out.exr"])
            for o, _, choices in options:
                for c in choices[1:]:
                    lines.append(["a.exr", "b.exr", f"{name}:{o}={c}"] + filled + ["-o", "o.exr"])
    lines += [
        ["--frames", "1-10x2", "shot.%04d.exr", "--blur", "9", "-o", "out.#.exr"],
        ["shot.1-3#.exr", "-d", "half", "-o", "out.@@@@.exr"],
        ["--threads", "2", "--maxmemory", "1.5G", "--timeout", "30", "-v", "--scene",
         "lights:width=64:height=32", "--defocus:focus=6:fstop=2", "-o", "dof.exr"],
        ["a.exr", "b.exr", "c.exr", "--deepmerge:n=3", "--flatten", "-o", "flat.exr"],
        ["a.exr", "k.exr", "--blur:kernel=image:iris=2", "21x11", "-o", "x.exr"],
    ]
    os.makedirs(corpus, exist_ok=True)
    for words in lines:
        data = "\0".join(words).encode()
        with open(os.path.join(corpus, hashlib.sha1(data).hexdigest()), "wb") as f:
            f.write(data)

    tokens = set()
    for name, args, options in commands:
        tokens.add(name)
        for o, d, choices in options:
            tokens.add(f":{o}=")
            tokens.update(choices)
    tokens.update(["-o", "#", "@@@@", "%04d", "1-10x2", "x", ",", "=", ":", "inf", "nan", "1e30",
                   "-1", "0", "2147483648", "\0"])
    with open(dict_path, "w") as f:
        f.write("# Tokens of bokehtool's command line (tests/fuzz/make_command_line_corpus.py)\n")
        for t in sorted(tokens):
            esc = "".join(f"\\x{ord(ch):02x}" if ch in '"\\' or not ch.isprintable() else ch for ch in t)
            f.write(f'"{esc}"\n')
    print(f"{len(lines)} seeds in {corpus}, {len(tokens)} tokens in {dict_path}")


main()
