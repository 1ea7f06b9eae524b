"""The files a Mitsuba XML scene reads, for the render store's key.

A scene file names meshes, textures, environment maps, volume grids, spectra and other XML
files (``<include>``); its images depend on their bytes as much as on its own, so a renderer's
fingerprint carries a digest of each (:func:`scene_files`), and an edited mesh or texture is
rendered again instead of a stored image being reused.

The XML files are the scene and every file its ``<include>`` tags name, transitively (any
extension), with those Mitsuba's own parser lists.  The names come from that parser where
Mitsuba has one (``mi.parser.parse_file``, as 3.9 has): every string property of every
object, with ``$name`` defaults, escapes, entities and the file's encoding applied as Mitsuba
applies them, without building a plugin.  A release without it, or a scene it refuses
(whose load fails too), fall back to regular expressions over the files' text: every
attribute value, as written and with each ``<default>`` value for its ``$names``.  Where the
names are looked up is a superset of the folders Mitsuba's file resolver may search: the
scene's, each XML file's, each ``<path>`` folder (taken from any folder before it, as Mitsuba
resolves one through the others), the working folder, and those of Mitsuba's file resolver
(the working folder it was imported in, any a user added).  Every file found under any of them is
hashed: a same-named file Mitsuba does not read can cost an extra render, a file it reads
is not missed.  One derived name is followed (a conductor's ``material`` reads
``data/ior/<material>.eta.spd`` and ``.k.spd``, which a scene's folder may shadow); files
under Mitsuba's own package are not (its version is in the key).
"""
from __future__ import annotations

import contextlib
import html
import itertools
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from harness.adapters.base import file_digest

__all__ = ["scene_files"]

_MAX_INCLUDE_DEPTH = 15   # Mitsuba's MI_XML_INCLUDE_MAX_RECURSION
_MAX_SPELLINGS = 64       # the fallback's spellings of one value with its $names replaced
_VALUE = re.compile(r"""=\s*(?:"([^"]*)"|'([^']*)')""")
_TAG = re.compile(r"<(default|path)\b([^>]*)>")
_INCLUDE = re.compile(r"""<include\b[^>]*?\bfilename\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_ATTRIBUTE = re.compile(r"""\b(name|value)\s*=\s*(?:"([^"]*)"|'([^']*)')""")


def scene_files(scene: Path, variant: str) -> dict[str, str]:
    """{file: SHA-256 digest (24 hex digits)} of every file the XML scene ``scene`` may read
    (see the module; ``variant``: the Mitsuba variant it is parsed for), its own file aside: a
    path relative to the scene's folder where the file lies under it, else absolute; sorted.
    A file that cannot be read has "unreadable: <reason>" for its digest: the scene's load, not
    its fingerprint, reports it."""
    scene = Path(scene).resolve()
    searched = _resolver_folders(variant)
    texts = _included(scene, searched)
    parsed = _parsed(scene, variant)
    if parsed is not None:
        texts.update((path, _text(path)) for path in parsed[0] if path not in texts)
    names = parsed[1] if parsed is not None else _values(texts)
    folders = _folders(scene, texts, searched)
    found = {(f / name).resolve() for name in names for f in folders if _is_file(f / name)}
    return {_name(p, scene.parent): _digest(p) for p in sorted((found | set(texts)) - {scene})}


def _parsed(scene: Path, variant: str) -> tuple[list[Path], set[str]] | None:
    """(the XML files it lists, every string property) by Mitsuba's parser; None where the
    release has no such parser or it refuses the scene."""
    from harness.adapters.mitsuba.runtime import using_variant

    try:
        with using_variant(variant) as mi, _resolver_kept(mi):
            state = mi.parser.parse_file(mi.parser.ParserConfig(variant), str(scene))
            names = set()
            for node in state.nodes:
                props = node.props
                for key in props.keys():
                    value = props[key]
                    if isinstance(value, str):
                        names.add(value)
                        if key == "material":   # a conductor's spectra, which a scene may shadow
                            names.update(f"data/ior/{value}.{part}.spd" for part in ("eta", "k"))
            return [Path(str(f)).resolve() for f in state.files], names
    except Exception:   # noqa: BLE001 - any failure of the parser: the fallback reads the text
        return None


@contextlib.contextmanager
def _resolver_kept(mi: Any) -> Iterator[None]:
    """Inside, Mitsuba's global file resolver is a copy of itself, and the resolver itself is
    put back after, untouched: ``mi.parser.parse_file`` leaves a scene's ``<path>`` folders
    in the resolver (3.9.1; ``mi.load_file`` does not), where every scene loaded after would
    search them (a fingerprint changing what a later render reads).  A release without a
    global resolver that can be set has nothing to keep."""
    if not (hasattr(mi, "file_resolver") and hasattr(mi, "set_file_resolver")):
        yield
        return
    resolver = mi.file_resolver()
    mi.set_file_resolver(mi.FileResolver(resolver))
    try:
        yield
    finally:
        mi.set_file_resolver(resolver)


def _included(scene: Path, searched: list[Path]) -> dict[Path, str]:
    """{XML file: its text} of the scene and of every file its <include> tags name,
    transitively (any extension, as Mitsuba includes; by regular expressions, so a file that
    holds only <default>s, which Mitsuba's parser does not list, is hashed too)."""
    texts = {scene: _text(scene)}
    for _ in range(_MAX_INCLUDE_DEPTH):
        folders = _folders(scene, texts, searched)
        names = {html.unescape(a or b) for text in texts.values() for a, b in _INCLUDE.findall(text)}
        named = {(f / v).resolve() for v in names for f in folders if _is_file(f / v)} - set(texts)
        if not named:
            break
        texts.update((path, _text(path)) for path in sorted(named))
    return texts


def _text(path: Path) -> str:
    try:
        return path.read_bytes().decode("utf-8", errors="replace")
    except OSError:
        return ""


def _tags(texts: dict[Path, str], tag: str) -> list[dict[str, str]]:
    """The name and value attributes of each <tag ...> of the texts, in order."""
    return [{k: html.unescape(a or b) for k, a, b in _ATTRIBUTE.findall(attributes)}
            for text in texts.values() for t, attributes in _TAG.findall(text) if t == tag]


def _values(texts: dict[Path, str]) -> set[str]:
    """Every attribute value of the texts, as written (entities read) and with each $name
    replaced by each value a <default> gives it, longer names first (at most _MAX_SPELLINGS
    spellings a value)."""
    defaults: dict[str, set[str]] = {}
    for pair in _tags(texts, "default"):
        if "name" in pair and "value" in pair:
            defaults.setdefault(pair["name"], set()).add(pair["value"])
    names = sorted(defaults, key=len, reverse=True)
    out: set[str] = set()
    for text in texts.values():
        for quoted in _VALUE.findall(text):
            value = html.unescape(quoted[0] or quoted[1])
            out.add(value)
            if "$" not in value:
                continue
            used = [n for n in names if "$" + n in value]
            for choice in itertools.islice(itertools.product(*(sorted(defaults[n]) for n in used)),
                                           _MAX_SPELLINGS):
                spelled = value
                for name, replacement in zip(used, choice):
                    spelled = spelled.replace("$" + name, replacement)
                out.add(spelled)
    return out


def _folders(scene: Path, texts: dict[Path, str], searched: list[Path]) -> list[Path]:
    """The scene's folder, each XML file's, each <path> folder (relative to any folder before
    it), the working folder and those ``searched`` (Mitsuba's file resolver's:
    :func:`_resolver_folders`)."""
    folders = list(dict.fromkeys([scene.parent, *(p.parent for p in texts), Path.cwd(), *searched]))
    for pair in _tags(texts, "path"):
        value = pair.get("value", "")
        folders += [(f / value).resolve() for f in list(folders) if value and _is_dir(f / value)]
    return list(dict.fromkeys(folders))


def _resolver_folders(variant: str) -> list[Path]:
    """The folders Mitsuba's file resolver searches beside a scene's: the working folder Mitsuba
    was imported in (which a later ``os.chdir`` does not move) and any a user added to it
    (``mi.file_resolver().append``: a folder of textures, say); Mitsuba's own package aside.
    Mitsuba's global resolver where it has one (3.9 has), else the calling thread's."""
    from harness.adapters.mitsuba.runtime import using_variant

    with using_variant(variant) as mi:
        resolver = mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()
        package = Path(mi.__file__).resolve().parent
        folders = [Path(str(resolver[i])).resolve() for i in range(len(resolver))]
    return [f for f in folders if f != package and package not in f.parents]


def _digest(path: Path) -> str:
    try:
        return file_digest(path)
    except OSError as e:   # a permission, a /proc file: recorded, not raised
        return f"unreadable: {e.strerror or type(e).__name__}"


def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except (OSError, ValueError):   # a name no file system takes (too long, a NUL)
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
