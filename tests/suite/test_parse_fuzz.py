"""The suite parser on any input: a Suite or a SuiteError naming the file, nothing else (no
AttributeError, TypeError, UnicodeDecodeError, ...).  Hypothesis draws random TOML documents
built from the suite's own keys, byte-level mutations of the shipped suites, and raw bytes; its
seed is fixed by the profile below (derandomize), so a run is reproducible."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.suite.parse import SuiteError, load_suite

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "suites").glob("*.toml"))
FUZZ = settings(max_examples=200, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

KEYS = ["name", "seed", "samples", "threads", "alpha", "batches", "replicas", "budgets", "measurements",
        "integrand", "techniques", "target", "max_samples", "params", "domain", "adapter", "scene",
        "integrator", "variant", "spp", "reference_spp", "reference_parts", "expect", "plugin", "wi",
        "kind", "points", "technique", "max_depth", "bitmap"]
TABLES = ["suite", "case", "sampler", "render"]
scalars = st.one_of(st.integers(min_value=-2**70, max_value=2**70), st.floats(allow_nan=True),
                    st.booleans(), st.text(max_size=12),
                    st.sampled_from(["all", "gaussian", "uniform", "hemisphere", "mitsuba", "pyrender",
                                     "furnace", "bias", "chi_square", "ggx", "path", "scalar_rgb", "edges",
                                     "1e12"]))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(KEYS), inner, max_size=3)), max_leaves=6)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if v != v else "inf" if v == float("inf") else "-inf" if v == float("-inf") else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"


@st.composite
def documents(draw) -> str:
    lines = []
    for _ in range(draw(st.integers(0, 5))):
        name = draw(st.sampled_from(TABLES))
        header = draw(st.sampled_from([f"[{name}]", f"[[{name}]]", f"{name} = {_toml_value(draw(values))}"]))
        lines.append(header)
        if header.startswith("["):
            for key, v in draw(st.dictionaries(st.sampled_from(KEYS), values, max_size=5)).items():
                lines.append(f"{key} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


def _parse(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "fuzz.toml"
    path.write_bytes(data)
    try:
        load_suite(path)
    except SuiteError as e:
        assert str(e).startswith(str(path)), e   # every error names the file first


@FUZZ
@given(doc=documents())
def test_random_suite_documents_give_a_suite_or_a_suite_error(tmp_path, doc):
    try:
        tomllib.loads(doc)
    except tomllib.TOMLDecodeError:
        pass  # still a fine input: it must give a SuiteError
    _parse(tmp_path, doc.encode())


@pytest.mark.parametrize("shipped", SHIPPED, ids=[p.name for p in SHIPPED])
@FUZZ
@given(data=st.data())
def test_mutated_shipped_suites_give_a_suite_or_a_suite_error(tmp_path, shipped, data):
    text = bytearray(shipped.read_bytes())
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text) - 1))
        op = data.draw(st.sampled_from(["replace", "delete", "insert"]))
        byte = data.draw(st.integers(0, 255))
        if op == "replace":
            text[at] = byte
        elif op == "delete":
            del text[at]
        else:
            text.insert(at, byte)
    _parse(tmp_path, bytes(text))


@FUZZ
@given(data=st.binary(max_size=200))
def test_any_bytes_give_a_suite_error(tmp_path, data):
    _parse(tmp_path, data)
