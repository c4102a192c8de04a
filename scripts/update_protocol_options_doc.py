"""Rewrites the protocol option reference block of docs/scene-format.md from
`imuemu protocol-options --markdown` (the option table in
drivers/protocols/protocol_options.cpp), which tests/cli/test_protocol_options.cpp
compares it with.

usage: python3 scripts/update_protocol_options_doc.py [IMUEMU]   (default build/release/daemon/imuemu)
"""
import pathlib
import subprocess
import sys

BEGIN = "<!-- BEGIN imuemu protocol-options --markdown -->"
END = "<!-- END imuemu protocol-options --markdown -->"

root = pathlib.Path(__file__).resolve().parent.parent
imuemu = sys.argv[1] if len(sys.argv) > 1 else str(root / "build/release/daemon/imuemu")
table = subprocess.run([imuemu, "protocol-options", "--markdown"], check=True, capture_output=True, text=True).stdout
doc_path = root / "docs/scene-format.md"
doc = doc_path.read_text()
head, rest = doc.split(BEGIN, 1)
_, tail = rest.split(END, 1)
doc_path.write_text(head + BEGIN + "\n" + table.strip("\n") + "\n" + END + tail)
print(f"{doc_path}: protocol option reference rewritten ({table.count(chr(10))} lines)")
