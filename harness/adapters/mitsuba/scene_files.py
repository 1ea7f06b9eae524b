"""The files a Mitsuba XML scene reads, for the render store's key.

A scene file names meshes, textures, environment maps, volume grids, spectra and other XML
files (``<include>``); its images depend on their bytes as much as on its own, so a renderer's
fingerprint carries a digest of each (:func:`scene_files`), and an edited mesh or texture is
rendered again instead of a stored image being reused.

Which files Mitsuba opens depends on rules of its parser that have changed between versions
(the order of ``<path>`` folders and the scene's folder, the folder an include's own includes
are resolved in, which ``<default>`` wins, how ``$name`` is replaced), so this module does not
imitate them: it takes a superset.  Every attribute value of the scene and of the XML files it
names (``$name`` replaced by each value any ``<default>`` gives it, and left as written), read
as a file name against every folder Mitsuba's resolver may search (the scene's, each XML
file's, each folder such a value names, the working folder), is a file the scene may read
wherever a file is there.  A file the scene does not read can only cost an extra render when
it changes; a file it reads cannot be missed (Mitsuba's own data files aside: its version is
in the key).  The values are read with a regular expression rather than an XML parser, so a
file Mitsuba's tolerant parser accepts (a comment holding ``--``, a bare ``&``) is read too.
"""
from __future__ import annotations

import html
import itertools
import re
from pathlib import Path

from harness.adapters.base import file_digest

__all__ = ["scene_files"]

_MAX_INCLUDE_DEPTH = 15   # Mitsuba's MI_XML_INCLUDE_MAX_RECURSION
_MAX_VARIANTS = 64        # spellings of one value with its $names replaced
_VALUE = re.compile(r"""=\s*(?:"([^"<]*)"|'([^'<]*)')""")
_DEFAULT = re.compile(r"<default\b([^>]*)>")
_ATTRIBUTE = re.compile(r"""\b(name|value)\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_COMMENT = re.compile(r"<!--.*?-->", re.S)


def scene_files(scene: Path) -> dict[str, str]:
    """{file: SHA-256 digest (24 hex digits)} of every file the XML scene ``scene`` may read
    (the module's superset), its own file aside: a path relative to the scene's folder where
    the file lies under it, else absolute; sorted."""
    scene = Path(scene).resolve()
    texts = {scene: _text(scene)}
    for _ in range(_MAX_INCLUDE_DEPTH):   # the XML files the values name, a level at a time
        folders, values = _folders(scene, texts), _values(texts)
        named = {(f / v).resolve() for v in values if v.lower().endswith(".xml") for f in folders
                 if _is_file(f / v)} - set(texts)
        if not named:
            break
        texts.update((path, _text(path)) for path in sorted(named))
    folders, values = _folders(scene, texts), _values(texts)
    files = {(f / v).resolve() for v in values for f in folders if _is_file(f / v)} - {scene}
    return {_name(p, scene.parent): file_digest(p) for p in sorted(files)}


def _text(path: Path) -> str:
    """An XML file's text, its comments dropped (a commented-out mesh is not read)."""
    return _COMMENT.sub("", path.read_bytes().decode("utf-8", errors="replace"))


def _values(texts: dict[Path, str]) -> set[str]:
    """Every attribute value of the texts, as written and with each $name replaced by each
    value a <default> of any of them gives it (longer names first, as Mitsuba replaces; a
    default's own $names too, to three levels)."""
    defaults: dict[str, set[str]] = {}
    for text in texts.values():
        for attributes in _DEFAULT.findall(text):
            pairs = {k: a or b for k, a, b in _ATTRIBUTE.findall(attributes)}
            if "name" in pairs and "value" in pairs:
                defaults.setdefault(pairs["name"], set()).add(pairs["value"])
    names = sorted(defaults, key=len, reverse=True)
    out: set[str] = set()
    for text in texts.values():
        for quoted in _VALUE.findall(text):
            raw = quoted[0] or quoted[1]
            spellings = {raw, html.unescape(raw)}   # as written, and its entities (&amp;) read
            for _ in range(3):
                spellings |= {v for s in spellings for v in _replaced(s, names, defaults)}
            out |= spellings
    return {v.strip() for v in out if v.strip()}


def _replaced(value: str, names: list[str], defaults: dict[str, set[str]]) -> list[str]:
    """value with its $names (longest first) replaced by each combination of their defaults'
    values, at most _MAX_VARIANTS of them."""
    used = [n for n in names if "$" + n in value]
    spelled = []
    for choice in itertools.islice(itertools.product(*(sorted(defaults[n]) for n in used)), _MAX_VARIANTS):
        v = value
        for name, replacement in zip(used, choice):
            v = v.replace("$" + name, replacement)
        spelled.append(v)
    return spelled


def _folders(scene: Path, texts: dict[Path, str]) -> list[Path]:
    """The folders Mitsuba's resolver may search: the scene's, each XML file's, the working
    folder, and each folder a value names relative to one of those (a <path> tag's)."""
    bases = list(dict.fromkeys([scene.parent, *(p.parent for p in texts), Path.cwd()]))
    named = [(b / v).resolve() for v in _values(texts) for b in bases if _is_dir(b / v)]
    return list(dict.fromkeys([*bases, *named]))


def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except (OSError, ValueError):   # a value no file system takes as a name (too long, a NUL)
        return False


def _is_dir(path: Path) -> bool:
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


def _name(path: Path, folder: Path) -> str:
    try:
        return path.relative_to(folder).as_posix()
    except ValueError:
        return str(path)
