"""The XMP packet of a JPEG: found in the file's bytes and parsed with the standard XML parser.

Drone makers write their attitude into XMP, as attributes (``drone-dji:GimbalPitchDegree="-89.90"``)
or as elements (``<drone-dji:GimbalPitchDegree>-89.90</...>``). ``read_xmp`` returns both kinds
by local name (the namespace prefix dropped), so one lookup serves every vendor's prefix.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

_START, _END = b"<x:xmpmeta", b"</x:xmpmeta>"


def xmp_packet(data: bytes) -> bytes | None:
    """The ``<x:xmpmeta>`` ... ``</x:xmpmeta>`` packet in a file's bytes, or None when it has none."""
    start = data.find(_START)
    if start < 0:
        return None
    end = data.find(_END, start)
    if end < 0:
        raise ValueError("XMP packet: <x:xmpmeta> is not closed (damaged file?)")
    return data[start:end + len(_END)]


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def read_xmp(data: bytes) -> dict[str, str]:
    """Every XMP property with a plain value, keyed by local name; empty when there is no packet."""
    packet = xmp_packet(data)
    if packet is None:
        return {}
    try:
        root = ET.fromstring(packet)
    except ET.ParseError as exc:
        raise ValueError(f"XMP packet: not well-formed XML ({exc})") from None
    values: dict[str, str] = {}
    for element in root.iter():
        for key, value in element.attrib.items():
            values.setdefault(_local(key), value)
        text = (element.text or "").strip()
        if text and len(element) == 0:
            values.setdefault(_local(element.tag), text)
    return values
