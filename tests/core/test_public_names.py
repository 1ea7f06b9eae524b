"""The compiled module ``reference_estimators._core`` is private: the harness, the reports, the
benchmarks and the tests reach the core only through the package's public names."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import reference_estimators as rest
from reference_estimators import kernels

CLIENTS = ("harness", "reports", "benchmarks", "tests")
PACKAGE = "reference_estimators"


def core_uses(path: Path) -> list[str]:
    """'line: code' of every import of ``_core`` from the package and every ``<alias>._core``
    where <alias> names the package in this file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    aliases = {PACKAGE}
    hits: list[int] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == PACKAGE:
                    aliases.add(a.asname or a.name)
                if a.name.startswith(f"{PACKAGE}._core"):
                    hits.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith(PACKAGE):
            if node.module.startswith(f"{PACKAGE}._core") or any(a.name == "_core" for a in node.names):
                hits.append(node.lineno)
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and node.attr == "_core" and isinstance(node.value, ast.Name)
                and node.value.id in aliases):
            hits.append(node.lineno)
    lines = path.read_text(encoding="utf-8").splitlines()
    return [f"{n}: {lines[n - 1].strip()}" for n in sorted(set(hits))]


def test_no_module_outside_the_package_uses_the_compiled_core(root):
    found = {}
    for folder in CLIENTS:
        for path in sorted((root / folder).rglob("*.py")):
            uses = core_uses(path)
            if uses:
                found[str(path.relative_to(root))] = uses
    assert not found, "use the public names of reference_estimators instead of _core:\n" + "\n".join(
        f"  {p}:{u}" for p, us in found.items() for u in us)


def test_the_guard_finds_every_form_of_access(tmp_path):
    src = tmp_path / "client.py"
    src.write_text("import reference_estimators as rest\nfrom reference_estimators import _core\n"
                   "import reference_estimators._core\nx = rest._core.CHUNK_SIZE\n"
                   "def _core(): pass\nclass S:\n    _core = None\ny = S()._core\n")
    assert [u.split(":")[0] for u in core_uses(src)] == ["2", "3", "4"]


@pytest.mark.parametrize("name", ["integrate_chunks", "estimate_from_states", "hardware_threads"])
def test_the_harness_helpers_are_public_and_documented(name):
    fn = getattr(rest, name)
    assert name in rest.__all__ and fn.__doc__ and len(fn.__doc__) > 40


@pytest.mark.parametrize("name", kernels.__all__)
def test_the_test_kernels_are_public_and_documented(name):
    assert getattr(kernels, name).__doc__
