"""SVG drawings read element by element, so that SVG's fill rules can decide what is solid.

In SVG every ``<path>``, ``<rect>``, ``<circle>``, ``<polygon>`` ... is a shape of its own, filled
by its ``fill-rule`` (``nonzero``, the default, or ``evenodd``) over its own subpaths only: a hole is
a subpath of the same path, and a shape drawn over another adds to it. trimesh reads a whole
drawing into one set of curves and forgets which element each came from, so each element is read
here on its own (with the transform of its groups) by ``trimesh.load_path``.

Elements without fill (``fill="none"``: outlines, as CAD programs export them) and elements that
are open on their own (separate ``<line>`` segments that only together close a curve) are read
together, as trimesh reads a whole drawing: their closed curves form one group whose holes follow
from nesting, like a DXF's. ``<text>`` is not geometry to trimesh; it is ignored with a note.
CSS style sheets are not read: only ``fill`` and ``fill-rule`` attributes and ``style`` declarations.
"""

from __future__ import annotations

import copy
import io
from dataclasses import dataclass

import numpy as np
import trimesh
from lxml import etree
from trimesh.exchange.common import XML_PARSER_OPTIONS
from trimesh.path.exchange.svg_io import element_transform

from engine.errors import GeometryError
from engine.geometry._shared import describe_error

_SHAPES = ("path", "rect", "circle", "polygon", "polyline", "line")  # what trimesh reads
_SVG = "http://www.w3.org/2000/svg"


@dataclass
class Shape:
    """Closed curves [p, 2] of one filled element and its fill rule; rule None: outlines, whose
    holes follow from nesting."""

    loops: list[np.ndarray]
    rule: str | None


def read_svg(name: str, data: bytes) -> tuple[list[Shape], list[str]]:
    """The filled shapes of an SVG drawing in document order (then one group of outlines), and
    notes on what was ignored."""
    try:
        root = etree.fromstring(data, parser=etree.XMLParser(**XML_PARSER_OPTIONS))
        elements = [e for e in root.iter(*(f"{{*}}{k}" for k in _SHAPES))]
        shapes, open_elements = [], []
        for element in elements:
            rule = None if _property(element, "fill", "black").strip() == "none" else _fill_rule(element)
            if _local(element) == "line":
                open_elements.append(element)
                continue
            path = _load([element])
            if len(path.dangling):
                open_elements.append(element)
            elif rule is None:
                open_elements.append(element)  # read with the other outlines, nested as a DXF's
            elif len(path.entities):
                shapes.append(Shape(_loops(path), rule))
        dangling = 0
        if open_elements:
            path = _load(open_elements)
            dangling = len(path.dangling)
            if len(path.entities) and path.discrete:
                shapes.append(Shape(_loops(path), None))
        texts = sum(1 for _ in root.iter("{*}text"))
    except MemoryError:
        raise
    except Exception as exc:  # noqa: BLE001 - any parser failure is a bad file to the user
        raise GeometryError(f"cannot read '{name}': {describe_error(exc, 'SVG drawing')}") from None
    notes = [f"ignored {dangling} open curves of the drawing"] if dangling else []
    if texts:
        notes.append(f"ignored {texts} text {'element' if texts == 1 else 'elements'} of the drawing:"
                     " convert text to paths in the drawing program to include it")
    return shapes, notes


def _local(element) -> str:
    return etree.QName(element).localname


def _load(elements: list) -> trimesh.path.Path2D:
    """The given elements as one drawing, each with the transform of its element and groups."""
    root = etree.Element(f"{{{_SVG}}}svg", nsmap={None: _SVG})
    for element in elements:
        m = element_transform(element)
        single = copy.deepcopy(element)
        single.tail = None
        single.set("transform", "matrix({!r},{!r},{!r},{!r},{!r},{!r})".format(
            *(float(v) for v in (m[0, 0], m[1, 0], m[0, 1], m[1, 1], m[0, 2], m[1, 2]))))
        root.append(single)
    return trimesh.load_path(io.BytesIO(etree.tostring(root)), file_type="svg")


def _loops(path) -> list[np.ndarray]:
    """The closed subpaths of one element in the direction they are drawn: the nonzero rule needs
    it, and ``Path2D.discrete`` may reverse a loop. Entities are stored in drawing order; each
    subpath chains them until it returns to its start."""
    loops, current = [], []
    scale = float(np.ptp(path.vertices, axis=0).max()) if len(path.vertices) else 1.0
    near = lambda p, q: bool(np.linalg.norm(p - q) <= 1e-9 * scale)  # noqa: E731
    for entity in path.entities:
        points = np.asarray(entity.discrete(path.vertices, scale=path.scale), dtype=np.float64)[:, :2]
        start = np.asarray(path.vertices[entity.points[0]], dtype=np.float64)[:2]
        if not near(points[0], start) and near(points[-1], start):
            points = points[::-1]  # an arc discretised against its drawn direction
        if current and near(current[-1][-1], points[0]):
            current.append(points[1:])
        else:
            current = [points]
        if len(current) and near(current[0][0], current[-1][-1]) and sum(len(c) for c in current) > 2:
            loops.append(np.concatenate(current)[:-1])
            current = []
    return loops


def _fill_rule(element) -> str:
    rule = _property(element, "fill-rule", "nonzero").strip()
    return "evenodd" if rule == "evenodd" else "nonzero"


def _property(element, name: str, default: str) -> str:
    """An inherited presentation property: a ``style`` declaration wins over the attribute of the
    same element, the nearest element that sets it over its ancestors."""
    node = element
    while node is not None and isinstance(node.tag, str):
        for declaration in node.get("style", "").split(";"):
            key, sep, value = declaration.partition(":")
            if sep and key.strip() == name:
                return value
        if node.get(name) is not None:
            return node.get(name)
        node = node.getparent()
    return default
