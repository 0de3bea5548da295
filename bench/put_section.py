#!/usr/bin/env python3
"""Puts a generated section (between `<!-- NAME:begin -->` and `<!-- NAME:end -->`) into
bench/RESULTS.md: replaces the file's section of that name, or appends it. bench/make_results.py
keeps these sections when compare.sh rewrites the file. Written atomically (a temporary file,
then a rename). Usage: put_section.py NAME SECTION_FILE (bench/dist.sh, bench/profile.sh)."""
import pathlib
import re
import sys

name, section_file = sys.argv[1], sys.argv[2]
section = pathlib.Path(section_file).read_text().strip() + "\n"
results = pathlib.Path(__file__).with_name("RESULTS.md")
text = results.read_text() if results.exists() else "# Benchmark results\n"
pattern = re.compile(rf"<!-- {name}:begin -->.*?<!-- {name}:end -->\n?", flags=re.S)
if pattern.search(text):
    text = pattern.sub(lambda _: section, text)
else:
    text = text.rstrip("\n") + "\n\n" + section
tmp = results.with_suffix(".md.tmp")
tmp.write_text(text)
tmp.replace(results)
