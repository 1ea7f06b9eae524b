"""Suites: parse a suite file (``parse``), plan the work units its measurements need
(``plan``), compute them on threads or Dask (``execute``), store them in SQLite (``store``),
and measure and judge every kind of case from what is stored (``run``)."""
from harness.suite.parse import Case, RenderCase, SamplerCase, Suite, SuiteError, load_suite

__all__ = ["Case", "RenderCase", "SamplerCase", "Suite", "SuiteError", "load_suite"]
