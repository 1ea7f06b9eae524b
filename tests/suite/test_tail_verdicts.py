"""A suite's bias verdicts on heavy tails: a team's infinite-variance estimator is
"inconclusive" (never "biased" by its tail), its firefly-clamped twin is "biased" and says
where it is clamped, in the table, the stored row and the failure text; the tails come from
every batch's contributions."""
import json
import sqlite3

import pytest

from harness.suite.parse import load_suite
from harness.suite.run import run_suite

MODULE = '''
import numpy as np


def pareto(u):                   # Pareto(1.5) of mean 1: infinite variance
    return u[:, 0] ** (-2 / 3) / 3


def firefly(u):                  # clamped at 164.6: the mean drops by 3 %
    return np.minimum(pareto(u), 164.6)
'''

SUITE = '''
[suite]
samples = 1_048_576
measurements = ["bias"]

[[case]]
estimator = "heavy:pareto"
dim = 1
reference = 1.0

[[case]]
estimator = "heavy:firefly"
dim = 1
reference = 1.0
'''


@pytest.fixture(scope="module")
def outcome(tmp_path_factory):
    repo = tmp_path_factory.mktemp("tails")
    (repo / "heavy.py").write_text(MODULE)
    (repo / "suite.toml").write_text(SUITE)
    return repo, run_suite(load_suite(repo / "suite.toml"), repo / "r.sqlite", threads=2)


def test_an_infinite_variance_is_inconclusive_and_its_clamped_twin_is_biased_where_it_is_clamped(outcome):
    repo, summary = outcome
    table = summary["estimator"].frame.set_index("technique")
    assert table.loc["pareto", "verdict"] in ("unbiased", "inconclusive")
    assert "heavy tail: tail index" in table.loc["pareto", "notes"]
    assert table.loc["firefly", "verdict"] == "biased"
    assert "clamped at 164.6 (" in table.loc["firefly", "notes"]
    failure = summary["estimator"].failures[1]
    assert "verdict: biased (clamped at 164.6 (" in failure


def test_the_stored_bias_row_keeps_the_tail_end(outcome):
    repo, _ = outcome
    with sqlite3.connect(repo / "r.sqlite") as con:
        details = [json.loads(d) for (d,) in con.execute(
            "SELECT detail FROM measurements WHERE measurement = 'bias' ORDER BY case_key")]
    ends = sorted(d["tail_end"] for d in details)
    assert ends[0] == "" and ends[1].startswith("clamped at 164.6 (")


def _tails_and_bias(summary):
    return [(r.bias.statistic, r.bias.pvalue, r.bias.verdict, r.bias.tail_index, r.bias.tail_end)
            for r in summary["estimator"].results]


def test_the_tails_come_from_the_state_units_and_equal_a_second_pass_over_every_batch(outcome, monkeypatch):
    """The bias test's state units carry their contributions' tails (no unit reads them again);
    where the units' tails cannot give the tail sample exactly (here: forced, one value kept per
    unit), a tail unit reads every batch again, and the verdicts are the same bits."""
    repo, summary = outcome
    with sqlite3.connect(repo / "r.sqlite") as con:
        kinds = dict(con.execute("SELECT kind, COUNT(*) FROM units GROUP BY kind").fetchall())
    assert set(kinds) == {"state"}
    import harness.suite.estimators as estimators

    keeps = estimators.tail_keeps
    monkeypatch.setattr(estimators, "tail_keeps", lambda *a: (keeps(*a)[0], 1))
    again = run_suite(load_suite(repo / "suite.toml"), repo / "again.sqlite", threads=2)
    with sqlite3.connect(repo / "again.sqlite") as con:
        kinds = dict(con.execute("SELECT kind, COUNT(*) FROM units GROUP BY kind").fetchall())
    assert kinds.get("tail") == 2   # one per case
    assert _tails_and_bias(again) == _tails_and_bias(summary)
