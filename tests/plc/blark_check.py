"""Parses each file given with blark and prints `OK` or `ERROR <first line of the error>`.

One Python process for the whole corpus (blark's grammar takes ~1 s to load). Used by
tests/plc_blark.rs; blark is installed in target/blark-venv by tests/install-deps.
"""
import sys

from blark.parse import parse_source_code

for path in sys.argv[1:]:
    with open(path, encoding="utf-8") as f:
        text = f.read()
    result = parse_source_code(text, fn=path)
    if result.exception is None:
        print(f"{path}\tOK")
    else:
        first = str(result.exception).strip().splitlines()
        print(f"{path}\tERROR\t{first[0] if first else type(result.exception).__name__}")
