#!/usr/bin/env python3
"""Writes a trial table (file,label[,split][,group]) for `tjepa --trials` from recordings whose
labels are in their file names.

  tools/trial_table.py --out fabric.csv --label '^([A-Za-z]+)_' --test '_2\\.csv$' \\
      ../shared/data/fabricslide/data/fabric/*.csv

--label REGEX   the label is the regex's first group in the file name (required)
--group REGEX   the group is the first group (or the whole match) in the file name
--test REGEX    files whose name matches are split test, the others train (no split column without)
--skip REGEX    files whose name matches are left out
Paths in the table are relative to the table's folder. A file whose name the label regex does not
match is an error naming it.
"""
import argparse
import os
import re
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--label", required=True)
    ap.add_argument("--group")
    ap.add_argument("--test")
    ap.add_argument("--skip")
    a = ap.parse_args()
    label, group = re.compile(a.label), re.compile(a.group) if a.group else None
    test, skip = re.compile(a.test) if a.test else None, re.compile(a.skip) if a.skip else None
    base = os.path.dirname(os.path.abspath(a.out))
    rows = []
    for f in sorted(a.files):
        name = os.path.basename(f)
        if skip and skip.search(name):
            continue
        m = label.search(name)
        if not m:
            sys.exit(f"trial_table: {f}: --label '{a.label}' does not match the file name")
        row = [os.path.relpath(os.path.abspath(f), base), m.group(1) if m.groups() else m.group(0)]
        if test:
            row.append("test" if test.search(name) else "train")
        if group:
            g = group.search(name)
            if not g:
                sys.exit(f"trial_table: {f}: --group '{a.group}' does not match the file name")
            row.append(g.group(1) if g.groups() else g.group(0))
        if any("," in v or '"' in v for v in row):
            row = ['"' + v.replace('"', '""') + '"' for v in row]
        rows.append(",".join(row))
    header = "file,label" + (",split" if test else "") + (",group" if group else "")
    os.makedirs(base, exist_ok=True)
    tmp = a.out + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(header + "\n" + "\n".join(rows) + "\n")
    os.replace(tmp, a.out)
    print(f"wrote {a.out}: {len(rows)} trials")


if __name__ == "__main__":
    main()
