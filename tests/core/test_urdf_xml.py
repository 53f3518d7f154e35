"""parse_urdf_xml: the one hardened XML read of a URDF (rewriters keep the text verbatim)."""

from __future__ import annotations

from pathlib import Path

import pytest
from lxml import etree

from robogs.format.errors import FormatError, InputError
from robogs.format.urdf import parse_urdf_xml

URDF = b"""<?xml version="1.0"?>
<robot name="r">
  <!-- a comment -->
  <link name="a"/>
</robot>
"""


def test_verbatim_keeps_comments_and_indentation(tmp_path: Path) -> None:
    p = tmp_path / "r.urdf"
    p.write_bytes(URDF)
    kept = etree.tostring(parse_urdf_xml(p, verbatim=True, keep_blank_text=True))
    assert kept == URDF.split(b"\n", 1)[1].rstrip(b"\n")
    stripped = parse_urdf_xml(p)
    assert [el.tag for el in stripped.iter()] == ["robot", "link"]
    assert etree.tostring(stripped) == b'<robot name="r"><link name="a"/></robot>'


def test_refusals(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="URDF not found"):
        parse_urdf_xml(tmp_path / "missing.urdf")
    bad = tmp_path / "bad.urdf"
    bad.write_bytes(b'<!DOCTYPE r [<!ENTITY x "y">]><robot name="r">&x;</robot>')
    with pytest.raises(FormatError, match="entities") as e:
        parse_urdf_xml(bad, verbatim=True)
    assert e.value.where == "<!DOCTYPE>"
    bad.write_bytes(b"<robot name='r'><link></robot>")
    with pytest.raises(FormatError, match="not well-formed XML"):
        parse_urdf_xml(bad)
