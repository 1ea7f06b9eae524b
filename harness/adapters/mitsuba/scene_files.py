"""The files a Mitsuba XML scene reads, for the render store's key.

A scene file names meshes, textures, environment maps, volume grids, spectra and other XML
files (``<include>``); its images depend on their bytes as much as on its own, so a renderer's
fingerprint carries a digest of each (:func:`scene_files`), and an edited mesh or texture is
rendered again instead of a stored image being reused (and a renderer that loaded the scene
reloads it when one of its files changed: :func:`stamp`).  The references are found as Mitsuba's
parser reads them: every ``filename`` attribute (``<include>``, ``<spectrum>``) and every
``<string name="filename">`` property, ``$name`` replaced by the scene's ``<default>`` values;
each resolved against the scene's folder, the folders its ``<path>`` tags add and the working
folder, the first that holds it (an included file's references too: Mitsuba 3.9 resolves
them against the scene's folder, not the included file's).  Included XML files are read in turn
(at most 15 levels deep, as Mitsuba).  A reference that no folder holds is listed as missing
(None): Mitsuba's loader, not the fingerprint, reports it.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

from harness.adapters.base import file_digest

__all__ = ["scene_files", "scene_references", "stamp"]

_MAX_INCLUDE_DEPTH = 15   # Mitsuba's MI_XML_INCLUDE_MAX_RECURSION
_PARAMETER = re.compile(r"\$(\w+)")


def scene_references(scene: Path) -> dict[str, Path | None]:
    """{reference as written (``$name`` replaced): the file it resolves to, or None where no
    folder holds it} for every file the XML scene ``scene`` reads, included XML files and what
    they read as well, sorted by reference.  ValueError naming the file where one is not
    well-formed XML."""
    scene = Path(scene).resolve()
    found: dict[str, Path | None] = {}
    _read(scene, scene, [scene.parent], {}, found, 0)
    return dict(sorted(found.items()))


def scene_files(scene: Path) -> dict[str, str | None]:
    """{reference: SHA-256 digest (24 hex digits) of its file, or None for a missing one} of
    :func:`scene_references`: what a fingerprint carries."""
    return {name: None if path is None else file_digest(path)
            for name, path in scene_references(scene).items()}


def stamp(paths: list[Path]) -> tuple:
    """(modification time in ns, size) of each file (None: not there): a cheap test of
    whether files changed since a scene was loaded from them."""
    stamps = []
    for path in paths:
        try:
            st = path.stat()
            stamps.append((st.st_mtime_ns, st.st_size))
        except OSError:
            stamps.append(None)
    return tuple(stamps)


def _read(xml: Path, scene: Path, folders: list[Path], defaults: dict[str, str],
          found: dict[str, Path | None], depth: int) -> None:
    try:
        root = ET.parse(xml).getroot()
    except (ET.ParseError, OSError) as e:
        raise ValueError(f"'scene': cannot read {xml} as XML: {e}") from None
    defaults = {**defaults, **{d.get("name", ""): d.get("value", "") for d in root.iter("default")}}
    folders = folders + [scene.parent / p.get("value", "") for p in root.iter("path")]

    def substituted(text: str) -> str:
        return _PARAMETER.sub(lambda m: defaults.get(m.group(1), m.group(0)), text)

    for element in root.iter():
        if element.tag == "string" and element.get("name") == "filename":
            reference = element.get("value")
        else:
            reference = element.get("filename")
        if reference is None:
            continue
        name = substituted(reference)
        if name in found:
            continue
        path = next(((f / name).resolve() for f in [*folders, Path.cwd()] if (f / name).is_file()), None)
        found[name] = path
        if path is not None and element.tag == "include" and depth + 1 < _MAX_INCLUDE_DEPTH:
            _read(path, scene, folders, defaults, found, depth + 1)
