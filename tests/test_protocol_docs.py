"""The UDP bridge's message table in docs/haptic.md is the code's.

The docs gave POSE 120 B and FORCE 240 B while the code sends and expects 116 and 232: a device
built from the docs got no answer. The table is now generated from the ``struct`` formats.
"""

import re
import struct
import subprocess
import sys

from conftest import ROOT

from fixplan.interactive import protocol


def _codes(fmt: str) -> list[str]:
    """The codes of a struct format, a repeat count kept with its code ("6d" is one, "3x" one)."""
    return re.findall(r"\d*[xcbB?hHiIlLqQnNefdspP]", fmt.lstrip("<>!=@"))


def test_the_docs_table_is_the_one_the_code_draws():
    proc = subprocess.run(
        [sys.executable, "tools/protocol_docs.py", "--check"], cwd=ROOT, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = (ROOT / "docs" / "haptic.md").read_text(encoding="utf-8")
    assert protocol.markdown_table() in doc


def test_the_documented_sizes_are_the_sizes_on_the_wire():
    doc = (ROOT / "docs" / "haptic.md").read_text(encoding="utf-8")
    rows = {
        m.group(1): (m.group(2), int(m.group(3)))
        for m in re.finditer(r"^\| (\w+) \| [^|]+ \| `([^`]+)`[^|]* \| (\d+) \+?\s*\|$", doc, re.M)
    }
    assert rows["POSE"] == ("<4sBBHId6d6d", protocol.POSE_SIZE) and protocol.POSE_SIZE == 116
    assert rows["FORCE"] == ("<4sBBHIIdd6d6d6dbBBxf6d", protocol.FORCE_SIZE) and protocol.FORCE_SIZE == 232
    # by hand: POSE = 4 + 1 + 1 + 2 + 4 + 8 + 2*48 = 116; FORCE = 4+1+1+2+4+4+8+8 + 3*48 + 1+1+1+1 + 4 + 48 = 232
    assert 4 + 1 + 1 + 2 + 4 + 8 + 2 * 48 == 116
    assert 4 + 1 + 1 + 2 + 4 + 4 + 8 + 8 + 3 * 48 + 1 + 1 + 1 + 1 + 4 + 48 == 232
    # a packet of the documented size is what the bridge sends and takes
    pose = protocol.encode_pose(1, 0.0, [0.0] * 6, [0.0] * 6, ndof=6)
    assert len(pose) == rows["POSE"][1]
    assert protocol.decode_pose(pose, 6).seq == 1


def test_every_field_of_every_message_is_named():
    for m in protocol.MESSAGES:
        assert len(_codes(m.layout.format)) == len(m.fields), m.name
        assert struct.calcsize(m.layout.format) == m.layout.size
