"""The suite parser (harness.suite.parse): what a valid suite of each kind turns into, its
defaults, and the message of every mistake (``file:line: key: what was expected``).

Deterministic: no random numbers.  Only the two Mitsuba tests load Mitsuba (a [[render]] or
adapter [[sampler]] table is validated by building its renderer or sampler)."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import reference_estimators as rest

from harness.suite.parse import MEASUREMENTS, SuiteError, load_suite

CASE = '[[case]]\nintegrand = "gaussian"\ntechniques = "uniform"\n'
HEAD = '[suite]\nname = "t"\nsamples = 1000\nbatches = 8\n\n'   # the next table starts on line 6


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "suite.toml"
    path.write_text(text, encoding="utf-8")
    return path


# --- valid suites ----------------------------------------------------------------------------------
def test_a_minimal_case_suite_takes_every_default(tmp_path):
    suite = load_suite(write(tmp_path, CASE))
    assert (suite.name, suite.seed, suite.samples, suite.threads) == ("suite", 0, 1_000_000, None)
    assert (suite.alpha, suite.batches, suite.replicas, suite.budgets) == (0.01, 64, 32, None)
    assert suite.samplers == () and suite.renders == ()
    (case,) = suite.cases
    assert (case.integrand, case.technique, case.samples) == ("gaussian", "uniform", 1_000_000)
    assert case.case_id == 0
    assert case.measurements == MEASUREMENTS
    assert MEASUREMENTS == ("bias", "variance", "convergence", "efficiency", "error_vs_time")
    assert (case.target, case.max_samples, case.looks) == (None, None, 1)


def test_all_integrands_and_techniques_expand_to_the_catalogue_in_order(tmp_path):
    suite = load_suite(write(tmp_path, '[[case]]\nintegrand = "all"\n'))
    expected = [(f.name, t) for f in rest.catalogue() for t in rest.techniques(f.name)]
    assert [(c.integrand, c.technique) for c in suite.cases] == expected
    assert [c.case_id for c in suite.cases] == list(range(len(expected)))


def test_suite_and_case_settings_override_the_defaults(tmp_path):
    text = ('[suite]\nname = "mine"\nseed = 7\nsamples = 4096\nthreads = 0\nalpha = 0.05\nbatches = 16\n'
            'replicas = 4\nbudgets = [4096, 64, 256, 64]\nmeasurements = ["variance", "bias", "variance"]\n\n'
            '[[case]]\nintegrand = "step"\ntechniques = ["rejection", "uniform"]\nsamples = 2048\n'
            'measurements = ["efficiency"]\n\n[[case]]\nintegrand = "peak"\ntechniques = "uniform"\n')
    suite = load_suite(write(tmp_path, text))
    assert (suite.name, suite.seed, suite.samples) == ("mine", 7, 4096)
    assert (suite.threads, suite.alpha) == (None, 0.05)   # threads = 0: all cores
    assert (suite.batches, suite.replicas, suite.budgets) == (16, 4, (64, 256, 4096))  # sorted, deduplicated
    assert [(c.technique, c.samples, c.measurements, c.case_id) for c in suite.cases] == [
        ("rejection", 2048, ("efficiency",), 0), ("uniform", 2048, ("efficiency",), 1),
        ("uniform", 4096, ("variance", "bias"), 2)]  # the suite's list, duplicates dropped, order kept


def test_a_precision_target_gives_one_look_per_doubling_up_to_max_samples(tmp_path):
    text = HEAD + '[[case]]\nintegrand = "gaussian"\ntarget = 1e-3\nmax_samples = {}\n'
    for max_samples, looks in ((1000, 1), (7999, 3), (8000, 4)):   # 1000, 2000, 4000 (, 8000)
        case = load_suite(write(tmp_path, text.format(max_samples))).cases[0]
        assert (case.target, case.max_samples, case.looks) == (1e-3, max_samples, looks)


def test_a_sampler_suite_needs_no_case_and_numbers_samplers_after_the_cases(tmp_path):
    text = (CASE + '[[sampler]]\nname = "exponential"\n\n[[sampler]]\nname = "trimmed_logistic"\n'
            'params = { s = 0.001, mu = 0.3 }\ndomain = "interval"\nsamples = 5000\n'
            'measurements = ["mcmc"]\n')
    suite = load_suite(write(tmp_path, text))
    first, second = suite.samplers
    assert (first.name, first.params, first.domain) == ("exponential", (), "half_line")   # the registry's
    assert (first.samples, first.measurements, first.case_id) == (1_000_000, ("chi_square",), 1)
    assert (first.adapter, first.label) == (None, "exponential")
    assert (second.params, second.domain, second.samples, second.measurements, second.case_id) == (
        (("mu", 0.3), ("s", 0.001)), "interval", 5000, ("mcmc",), 2)
    assert second.label == "trimmed_logistic(mu=0.3, s=0.001)"
    alone = load_suite(write(tmp_path, '[[sampler]]\nname = "ggx"\nparams = { alpha = 0.1 }\n'))
    assert alone.cases == () and alone.samplers[0].case_id == 0


def test_a_suite_of_core_cases_and_samplers_imports_no_renderer(tmp_path):
    path = write(tmp_path, CASE + '[[sampler]]\nname = "exponential"\n')
    code = ("import sys; from harness.suite.parse import load_suite; load_suite(sys.argv[1]); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('mitsuba', 'drjit', 'pyrender', 'OpenGL', 'OpenImageIO')))")
    r = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120,
                       check=False)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr


def test_a_mitsuba_render_table_makes_one_case_per_list_element_with_defaults(tmp_path):
    text = '[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nintegrator = ["path", "ptracer"]\n'
    suite = load_suite(write(tmp_path, text))
    assert suite.cases == () and suite.samplers == ()
    path, ptracer = suite.renders
    assert path.spec == (("integrator", "path"), ("scene", "furnace"))
    assert ptracer.spec == (("integrator", "ptracer"), ("scene", "furnace"))
    assert (path.case_id, ptracer.case_id) == (0, 1)   # render cases are numbered on their own
    assert (path.scene, path.label) == ("mitsuba:furnace", "integrator=path")
    # spp 64; budgets spp/64, spp/16, spp/4, spp; reference 64 x the largest budget in 8 parts
    assert (path.spp, path.replicas, path.budgets) == (64, 16, (1, 4, 16, 64))
    assert (path.reference_spp, path.reference_parts, path.expect) == (4096, 8, "unbiased")
    assert path.measurements == MEASUREMENTS


def test_a_render_table_can_name_a_sibling_configuration_as_the_reference(tmp_path):
    text = ('[[render]]\nadapter = "mitsuba"\nscene = "cornell"\nintegrator = ["path", "ptracer"]\n'
            'reference = { integrator = "path" }\n')
    path, ptracer = load_suite(write(tmp_path, text)).renders
    assert path.reference_config is None                  # the sibling itself: its usual reference
    assert ptracer.reference_config == path.spec
    # adapter keys may hold tables (a python adapter's params): still found
    text = ('[[render]]\nadapter = "python"\nfunction = "flat:render"\nscene = "flat"\n'
            'params = [{ gain = 1.0 }, { gain = 1.05 }]\nreference = { params = { gain = 1.0 } }\n')
    (tmp_path / "flat.py").write_text("def render(spp, seed, gain=1.0):\n    return None\n")
    one, other = load_suite(write(tmp_path, text)).renders
    assert one.reference_config is None and other.reference_config == one.spec


def test_a_mitsuba_sampler_table_is_labelled_and_keeps_its_spec(tmp_path):
    text = '[[sampler]]\nadapter = "mitsuba"\nplugin = { type = "diffuse" }\nvariant = "scalar_rgb"\n'
    (sc,) = load_suite(write(tmp_path, text)).samplers
    assert (sc.adapter, sc.domain, sc.samples, sc.measurements) == ("mitsuba", "hemisphere", 1_000_000,
                                                                    ("chi_square", "weight"))
    assert sc.spec == '{"plugin": {"type": "diffuse"}, "variant": "scalar_rgb"}'
    assert sc.label.startswith("mitsuba:diffuse") and sc.label.endswith("[scalar_rgb]")


def test_an_area_light_table_keeps_its_reference_point(tmp_path):
    text = ('[[sampler]]\nadapter = "mitsuba"\nref = [0.0, 0.0, 0.5]\nplugin = { type = "sphere", '
            'center = [0, 0, 2], radius = 0.5, emitter = { type = "area", radiance = 1.0 } }\n')
    (sc,) = load_suite(write(tmp_path, text)).samplers
    assert (sc.domain, sc.measurements) == ("sphere", ("chi_square", "weight"))
    assert sc.label == "mitsuba:area sphere constant from (0, 0, 0.5)"
    assert json.loads(sc.spec)["ref"] == [0.0, 0.0, 0.5]
    text = ('[[sampler]]\nadapter = "mitsuba"\nref = [0.0, 0.0, 0.5]\nplugin = { type = "diffuse" }\n')
    with pytest.raises(SuiteError, match="'ref': only emitters on shapes"):
        load_suite(write(tmp_path, text))


# --- mistakes ----------------------------------------------------------------------------------
# (file text, line or None, key or None, fragment of what was expected)
MISTAKES = {
    # unknown tables and keys
    "unknown table": (
        '[suites]\nname = "x"\n',
        1, "suites", "unknown table 'suites'; expected [suite], [[case]], [[sampler]] and [[render]] tables"),
    "unknown suite key": (
        '[suite]\nsample = 10\n\n' + CASE,
        2, "sample", "unknown key 'sample'; expected one of: name, seed, samples, threads, alpha"),
    "unknown case key": (
        HEAD + CASE + 'colour = "red"\n',
        9, "colour", ("unknown key 'colour'; expected one of: "
            "integrand, techniques, samples, measurements, target, max_samples")),
    "unknown sampler key": (
        HEAD + '[[sampler]]\nname = "ggx"\nsize = 3\n',
        8, "size", "unknown key 'size'"),
    "unknown adapter key": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nscenery = "furnace"\n',
        8, "scenery", "unknown key for adapter 'mitsuba'; expected one of"),
    "no table": (
        '[suite]\nsamples = 1000\n',
        None, "case", "expected at least one [[case]], [[sampler]] or [[render]] table"),
    "no integrand": (
        HEAD + '[[case]]\ntechniques = "all"\n',
        6, None, "missing key 'integrand' (a catalogue name or \"all\")"),
    # wrong types
    "str for int": (
        '[suite]\nsamples = "many"\n\n' + CASE,
        2, "samples", "expected int, got str 'many'"),
    "bool for int": (
        '[suite]\nseed = true\n\n' + CASE,
        2, "seed", "expected int, got bool True"),
    "str for float": (
        '[suite]\nalpha = "0.01"\n\n' + CASE,
        2, "alpha", "expected int or float, got str '0.01'"),
    "int for str": (
        HEAD + '[[case]]\nintegrand = 3\n',
        7, "integrand", "expected str, got int 3"),
    "int for techniques": (
        HEAD + '[[case]]\nintegrand = "gaussian"\ntechniques = 3\n',
        8, "techniques", "expected str or list, got int 3"),
    "str for list": (
        HEAD + CASE + 'measurements = "bias"\n',
        9, "measurements", "expected list, got str 'bias'"),
    "str for params": (
        HEAD + '[[sampler]]\nname = "ggx"\nparams = "alpha"\n',
        8, "params", "expected dict, got str 'alpha'"),
    # measurement names
    "unknown measurement": (
        '[suite]\nmeasurements = ["bais"]\n\n' + CASE,
        2, "measurements", ("unknown measurement 'bais'; expected some of: bias, variance, convergence, "
            "efficiency, error_vs_time")),
    "sampler check in suite": (
        '[suite]\nmeasurements = ["mcmc"]\n\n' + CASE,
        2, "measurements", ("unknown measurement 'mcmc'; expected some of: bias, variance, convergence, "
            "efficiency, error_vs_time (sampler checks go in [[sampler]] tables)")),
    "no measurement": (
        HEAD + CASE + 'measurements = []\n',
        9, "measurements", "expected at least one measurement"),
    "unknown sampler measurement": (
        HEAD + '[[sampler]]\nname = "ggx"\nmeasurements = ["bias"]\n',
        8, "measurements", ("unknown sampler measurement 'bias'; expected some of: "
            "chi_square, mcmc, weight")),
    "weight of a catalogue sampler": (
        HEAD + '[[sampler]]\nname = "ggx"\nmeasurements = ["weight"]\n',
        8, "measurements", "'weight' (sample weight == eval/pdf) applies to renderer samplers"),
    "render measurement": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nmeasurements = ["chi_square"]\n',
        8, "measurements", "unknown measurement 'chi_square'"),
    # counts and budgets
    "zero samples": (
        '[suite]\nsamples = 0\n\n' + CASE,
        2, "samples", "expected a budget > 0 samples, got 0"),
    "negative case samples": (
        HEAD + CASE + '\n[[case]]\nintegrand = "step"\nsamples = -3\n',
        12, "samples", "expected a budget > 0 samples, got -3"),
    "fewer samples than batches": (
        HEAD + CASE + 'samples = 7\n',
        9, "samples", "expected at least batches = 8 samples, got 7"),
    "negative seed": (
        '[suite]\nseed = -1\n\n' + CASE,
        2, "seed", "expected an integer in [0, 2**64), got -1"),
    "seed beyond 64 bits": (
        '[suite]\nseed = 18446744073709551616\n\n' + CASE,
        2, "seed", "expected an integer in [0, 2**64), got 18446744073709551616"),
    "negative threads": (
        '[suite]\nthreads = -2\n\n' + CASE,
        2, "threads", "expected an integer >= 0 (0: all cores), got -2"),
    "alpha out of range": (
        '[suite]\nalpha = 0\n\n' + CASE,
        2, "alpha", "expected a false-alarm rate in (0, 1), got 0"),
    "too few batches": (
        '[suite]\nbatches = 7\n\n' + CASE,
        2, "batches", "expected an integer in [8, samples = 1000000], got 7"),
    "more batches than samples": (
        '[suite]\nsamples = 100\nbatches = 101\n\n' + CASE,
        3, "batches", "expected an integer in [8, samples = 100], got 101"),
    "one replica": (
        '[suite]\nreplicas = 1\n\n' + CASE,
        2, "replicas", "expected at least 2 replicas, got 1"),
    "two budgets": (
        '[suite]\nbudgets = [64, 256]\n\n' + CASE,
        2, "budgets", "expected at least 3 positive integer budgets, got [64, 256]"),
    "zero budget": (
        '[suite]\nbudgets = [64, 0, 256]\n\n' + CASE,
        2, "budgets", "expected at least 3 positive integer budgets, got [64, 0, 256]"),
    "too few sampler samples": (
        HEAD + '[[sampler]]\nname = "ggx"\nsamples = 999\n',
        8, "samples", "expected 1000 to 100,000,000 samples (a check holds its samples in memory), got 999"),
    "too many sampler samples": (   # had run into a MemoryError
        HEAD + '[[sampler]]\nname = "ggx"\nsamples = 1099511627776\n',
        8, "samples", "expected 1000 to 100,000,000 samples (a check holds its samples in memory), got "
                      "1,099,511,627,776"),
    "zero spp": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nspp = 0\n',
        8, "spp", "expected a budget > 0 samples, got 0"),
    "too few render replicas": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nreplicas = 3\n',
        8, "replicas", "expected at least 4 replicas, got 3"),
    "too few distinct render budgets": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nspp = 1\n',
        8, "spp", ("expected at least 3 distinct budgets for bias, variance, convergence, "
            "efficiency, error_vs_time, got [1] (give budgets)")),
    "one reference part": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nreference_parts = 1\n',
        8, "reference_parts", "expected at least 2 independent parts, got 1"),
    "spp beyond 32 bits": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nspp = 1_000_000_000_000\n',
        8, "spp", "expected at most 2,147,483,647 samples per pixel per render"),
    "render budgets beyond 32 bits": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nbudgets = [1, 2, 4294967296]\n',
        8, "budgets", "expected at most 2,147,483,647 samples per pixel per render"),
    "more renders than a suite may plan": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nreplicas = 2_000_000\n',
        6, "render", "10,000,008 renders (10,000,008 in the suite); a suite may plan at most 1,048,576"),
    "a bias batch too big to hold": (
        '[suite]\nsamples = 20_000_000_000\nmeasurements = ["bias"]\n\n' + CASE,
        2, "samples", "the bias test's tail sample holds one batch of 312,500,000 contributions in memory; "
                      "at most 268,435,456"),
    "more samples than a suite may plan": (
        '[suite]\nsamples = 1_000_000_000_000_000\nmeasurements = ["convergence"]\n\n' + CASE,
        2, "samples", "1e+15 samples need "),
    "reference spp not a multiple": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nreference_spp = 100\n' 'reference_parts = 8\n',
        8, "reference_spp", "expected a multiple of reference_parts = 8, got 100"),
    # names that are not in a registry
    "unknown integrand": (
        HEAD + '[[case]]\nintegrand = "gausian"\n',
        7, "integrand", "unknown integrand 'gausian'; the catalogue has: gaussian, polynomial"),
    "unknown technique": (
        HEAD + '[[case]]\nintegrand = "gaussian"\ntechniques = ["uniform", "mis"]\n',
        8, "techniques", ("unknown technique 'mis' for integrand 'gaussian'; expected one of: "
            "uniform, uniform/stratified")),
    "unknown technique (one name)": (
        HEAD + '[[case]]\nintegrand = "step"\ntechniques = "nope"\n',
        8, "techniques", "unknown technique 'nope' for integrand 'step'"),
    "unknown sampler": (
        HEAD + '[[sampler]]\nname = "gxx"\n',
        7, "name", "unknown sampler 'gxx'; expected one of: exponential, linear"),
    "tabulated sampler": (
        HEAD + '[[sampler]]\nname = "piecewise_constant_1d"\n',
        7, "name", "sampler 'piecewise_constant_1d' needs a table of values: test it from Python"),
    "bad sampler parameter": (
        HEAD + '[[sampler]]\nname = "cosine_hemisphere"\nparams = { foo = 1 }\n',
        8, "params", "sampler 'cosine_hemisphere' has no parameter 'foo'"),
    "unknown domain": (
        HEAD + '[[sampler]]\nname = "ggx"\ndomain = "torus"\n',
        8, "domain", "expected one of: interval, half_line, square, disk, hemisphere, sphere, got 'torus'"),
    "unknown adapter": (
        HEAD + '[[render]]\nadapter = "blender"\n',
        7, "adapter", "expected one of: mitsuba, pyrender, command, python (or an adapter registered under "
                      "the entry-point group 'harness.adapters'), got 'blender'"),
    "unknown scene": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nscene = "nosuch"\n',
        8, "scene", "'nosuch' is neither a built-in scene"),
    "unknown expectation": (
        HEAD + '[[render]]\nadapter = "mitsuba"\nexpect = "maybe"\n',
        8, "expect", "expected \"unbiased\" or \"biased\", got 'maybe'"),
    "sampler of another adapter": (
        HEAD + '[[sampler]]\nadapter = "pyrender"\n',
        7, "adapter", ("expected \"mitsuba\" (samplers of other adapters are not supported), "
            "got 'pyrender'")),
    # precision targets
    "target without max_samples": (
        HEAD + CASE + 'target = 1e-3\n',
        9, "target", "a target needs max_samples, the most samples to try"),
    "max_samples without target": (
        HEAD + CASE + 'max_samples = 4000\n',
        9, "max_samples", "max_samples only applies with a target"),
    "max_samples below samples": (
        HEAD + CASE + 'target = 1e-3\nmax_samples = 10\n',
        10, "max_samples", "expected at least samples = 1000, got 10"),
    "unreachable target": (
        HEAD + CASE + 'target = 0.0\nmax_samples = 4000\n',
        9, "target", "no budget can reach a half-width of 0: it must be > 0 and above the rounding floor"),
    # the document's shape (issue 18: these raised AttributeError / TypeError)
    "a single [render] table": (
        '[render]\nadapter = "mitsuba"\n', 1, "render",
        "expected [[render]] tables (an array of tables), got a single [render] table"),
    "render = 5": ('render = 5\n', 1, "render", "expected [[render]] tables, got 5"),
    "sampler = [1, 2]": ('sampler = [1, 2]\n', 1, "sampler", "expected [[sampler]] tables, got [1, 2]"),
    "case = [\"x\"]": ('case = ["x"]\n', 1, "case", "expected [[case]] tables, got ['x']"),
    "suite = 3": ('suite = 3\n' + CASE, 1, "suite", "expected a [suite] table, got 3"),
    "render without adapter": (
        '[[render]]\nscene = "furnace"\n', 1, None,
        "missing key 'adapter' (one of: mitsuba, pyrender, command, python)"),
    "sampler without name": (
        '[[sampler]]\ndomain = "sphere"\n', 1, None, "missing key 'name' (a catalogue sampler"),
    "no techniques": (
        HEAD + '[[case]]\nintegrand = "gaussian"\ntechniques = []\n', 8, "techniques",
        "expected \"all\", a technique or a non-empty list of techniques, got []"),
    "sibling reference of an unknown key": (
        '[[render]]\nadapter = "mitsuba"\nscene = "cornell"\nintegrator = ["path", "ptracer"]\n'
        'reference = { sampler = "x" }\n', 5, "reference", "expected adapter keys of this table (scene, "
        "integrator), got 'sampler'"),
    "sibling reference naming no configuration": (
        '[[render]]\nadapter = "mitsuba"\nscene = "cornell"\nintegrator = ["path", "ptracer"]\n'
        'reference = { integrator = "direct" }\n', 5, "reference",
        "{integrator = 'direct'} names no configuration of this [[render]] table"),
    "sibling reference without the bias test": (
        '[[render]]\nadapter = "mitsuba"\nscene = "cornell"\nintegrator = ["path", "ptracer"]\n'
        'reference = { integrator = "path" }\nmeasurements = ["convergence"]\nbudgets = [1, 4, 16]\n', 5,
        "reference", "needs the 'bias' measurement"),
    "no scenes": (
        '[[render]]\nadapter = "mitsuba"\nscene = []\n', 3, "scene",
        "expected a value or a non-empty list of values, got []"),
    # tables written without headers, and sub-tables: had been named without a line
    "a dotted suite key": (
        'suite.samples = -1\n\n' + CASE, 1, "samples", "expected a budget > 0 samples, got -1"),
    "an inline suite table": (
        'suite = { name = "t", samples = -1 }\n\n' + CASE, 1, "samples", "expected a budget > 0 samples"),
    "an inline array of cases": (
        'case = [\n  { integrand = "gaussian" },  # {braces} in a comment\n  { integrand = "nope" },\n]\n', 3,
        "integrand", "unknown integrand 'nope'"),
    "a case's sub-table": (
        CASE + '\n[case.colour]\nred = 1\n', 5, "colour", "unknown key 'colour'"),
    "a dotted suite key before an inline array": (   # had named the array's line
        'suite.samples = 50\ncase = [{ integrand = "gaussian", techniques = "uniform" }]\n', 1, "batches",
        "expected an integer in [8, samples = 50], got 64"),
    "an inline array past multi-line strings": (     # their quotes and braces had ended the scan
        "case = [\n  { integrand = \"gaussian\", xfail = '''it's {odd}''' },\n"
        '  { integrand = "gaussian", xfail = """a 5" {screen}""" },\n  { integrand = "nope" },\n]\n', 4,
        "integrand", "unknown integrand 'nope'"),
}


@pytest.mark.parametrize("text, line, key, fragment", MISTAKES.values(), ids=MISTAKES.keys())
def test_each_mistake_names_file_line_key_and_what_was_expected(tmp_path, text, line, key, fragment):
    path = write(tmp_path, text)
    where = f"{path}:{line}: " if line else f"{path}: "
    with pytest.raises(SuiteError, match="^" + re.escape(where + (f"{key}: " if key else "")) + ".*"
                       + re.escape(fragment)):
        load_suite(path)


def test_a_toml_syntax_error_names_the_file_and_the_line(tmp_path):
    path = write(tmp_path, '[suite]\nsamples = = 3\n')
    with pytest.raises(SuiteError, match="^" + re.escape(f"{path}: not valid TOML: ") + ".*line 2"):
        load_suite(path)


def test_a_missing_file_names_the_path_and_why(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(SuiteError, match="^" + re.escape(f"{path}: cannot read suite file: No such file")):
        load_suite(path)


def test_non_utf8_bytes_are_named_with_their_offset(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes('[suite]\nname = "caf\u00e9"\n'.encode("latin-1"))
    with pytest.raises(SuiteError, match="^" + re.escape(f"{path}: not UTF-8 text: byte 0xe9 at offset 19")):
        load_suite(path)


@pytest.mark.parametrize("name, file_name", [("default", "default"), ("../../../x", "x"),
                                             ("my suite/v2", "my_suite_v2"), ("..", "suite")])
def test_a_suite_name_becomes_a_safe_file_name(tmp_path, name, file_name):
    suite = load_suite(write(tmp_path, f'[suite]\nname = "{name}"\n\n' + CASE))
    assert suite.name == name and suite.file_name == file_name


def test_suite_errors_are_value_errors():
    assert issubclass(SuiteError, ValueError)  # callers that catch ValueError see them too


def test_the_runs_alpha_is_split_over_the_families_its_definition_holds(tmp_path):
    """One α for a whole run: Bonferroni over the families the suite file defines (never over
    what the data turn out to be), Holm within each."""
    mixed = load_suite(write(tmp_path, HEAD.replace("batches", "alpha = 0.02\nbatches") + CASE
                             + '[[sampler]]\nname = "ggx"\n'
                             '[[render]]\nadapter = "mitsuba"\nscene = "furnace"\nmeasurements = ["bias"]\n'))
    assert mixed.families == ("estimator bias", "estimator convergence", "sampler checks", "render bias")
    assert mixed.family_alpha == 0.02 / 4
    only = load_suite(write(tmp_path, '[[sampler]]\nname = "ggx"\n'))
    assert only.families == ("sampler checks",) and only.family_alpha == only.alpha == 0.01
