"""What a suite holds, once parsed (harness.suite.parse): the suite, its estimator cases,
sampler checks and render cases, as frozen values that key work units and travel to workers."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["SuiteError", "MEASUREMENTS", "SAMPLER_MEASUREMENTS", "Suite", "Case", "SamplerCase", "RenderCase"]


class SuiteError(ValueError):
    """A suite file that cannot be run; the message names file, line and key."""


MEASUREMENTS = ("bias", "variance", "convergence", "efficiency", "error_vs_time")
SAMPLER_MEASUREMENTS = ("chi_square", "mcmc", "weight")


@dataclass(frozen=True)
class SamplerCase:
    """A catalogue sampler checked against its pdf (harness.samplers.check)."""

    name: str
    params: tuple[tuple[str, float], ...]
    domain: str
    samples: int
    case_id: int
    measurements: tuple[str, ...] = ("chi_square",)
    adapter: str | None = None   # "mitsuba": a renderer's sampler (``spec`` holds its keys as JSON)
    spec: str = ""
    xfail: str = ""              # a known finding: its failure is expected (strict)
    target: str = ""             # a user's sampler: its module:attr (``name`` is then the target)
    source: str = ""             # ... fingerprint of its source (harness.usercode)
    total: float | None = None   # ... its pdf's integral where some u give no sample
    udim: int | None = None      # ... uniforms per sample (default: the domain's)

    @property
    def label(self) -> str:
        if self.adapter:
            return f"{self.adapter}:{self.name}"
        return self.name + ("(" + ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v!r}"
                                            for k, v in self.params) + ")" if self.params else "")


@dataclass(frozen=True)
class RenderCase:
    """A renderer configuration (harness.adapters) measured from replica renders.

    ``spec`` holds the adapter's keys (scene, integrator, points, ...); ``spp`` is the budget
    (samples or frames per pixel) of each of the bias test's ``replicas`` renders; ``budgets``
    those of the convergence renders; a scene without an exact answer is compared with
    ``reference_parts`` independent renders of ``reference_spp`` in total, or, where
    ``reference_config`` names another configuration of the same table (its ``spec``), with that
    configuration's bias-test replicas (two renderers compared without a converged reference).
    """

    adapter: str
    spec: tuple[tuple[str, Any], ...]
    case_id: int
    spp: int
    replicas: int
    budgets: tuple[int, ...]
    reference_spp: int
    reference_parts: int
    measurements: tuple[str, ...]
    expect: str = "unbiased"           # or "biased": the bias test must then reject
    xfail: str = ""                    # a known finding: its failure is expected (strict)
    base: str = ""                     # the suite file's folder: adapters resolve paths there
    scene_name: str = ""               # the renderer's own description (Renderer.describe()) ...
    config: str = ""                   # ... of its scene and configuration, where it has one
    reference_config: tuple[tuple[str, Any], ...] | None = None   # the sibling measured against

    @property
    def scene(self) -> str:
        return f"{self.adapter}:{self.scene_name or dict(self.spec).get('scene', '?')}"

    @property
    def label(self) -> str:
        """The configuration without its scene, e.g. "integrator=path, variant=scalar_rgb"
        (or what the renderer says distinguishes it, e.g. a command adapter's command)."""
        if self.config:
            return self.config
        return ", ".join(f"{k}={v}" for k, v in self.spec if k != "scene") or self.adapter


@dataclass(frozen=True)
class Case:
    """An estimator case: a catalogue integrand x technique, or a user's estimator
    (``estimator`` = "module:attr" or "file.py:attr", a callable u (N, dim) -> contributions
    (N,) of ``reference``; ``integrand`` is then the target and ``technique`` its label)."""

    integrand: str
    technique: str
    samples: int
    case_id: int  # position in the suite: keys the case's random streams
    measurements: tuple[str, ...] = MEASUREMENTS
    target: float | None = None      # stop the bias test's sample doubling at this CI half-width
    max_samples: int | None = None   # ... or at this many samples
    label: str = ""                  # what tables call it; a baseline is named by it
    baseline: str = ""               # label of the case its efficiency is compared with
    xfail: str = ""                  # a known finding: its failure is expected (strict)
    estimator: str = ""              # a user's estimator: its module:attr target
    dim: int = 0                     # ... canonical uniforms per sample
    reference: float = math.nan      # ... the exact value
    points: str = "random"           # ... random, stratified or sobol
    source: str = ""                 # ... fingerprint of its source (harness.usercode)

    @property
    def name(self) -> str:
        """The label, or integrand/technique."""
        return self.label or f"{self.integrand}/{self.technique}"

    @property
    def looks(self) -> int:
        """How many budgets a target may try: samples, 2 samples, ... <= max_samples."""
        if self.target is None or self.max_samples is None:
            return 1
        k = 1
        while self.samples << k <= self.max_samples:
            k += 1
        return k


@dataclass(frozen=True)
class Suite:
    name: str
    path: Path
    seed: int
    samples: int
    threads: int | None
    cases: tuple[Case, ...]
    alpha: float = 0.01
    batches: int = 64
    replicas: int = 32
    budgets: tuple[int, ...] | None = None
    samplers: tuple[SamplerCase, ...] = ()
    renders: tuple[RenderCase, ...] = ()
    revision: str = ""                 # SHA-256 of the suite file's text (which edit was run)

    @property
    def families(self) -> tuple[str, ...]:
        """The families of tests the suite's definition holds (not its data): estimator bias,
        estimator convergence, sampler checks, render bias, render convergence."""
        wants = [("estimator bias", self.cases, ("bias",)),
                 ("estimator convergence", self.cases, ("convergence",)),
                 ("sampler checks", self.samplers, None),
                 ("render bias", self.renders, ("bias",)),
                 ("render convergence", self.renders, ("convergence",))]
        return tuple(name for name, cases, ms in wants
                     if any(ms is None or set(ms) & set(c.measurements) for c in cases))

    @property
    def family_alpha(self) -> float:
        """The level each family is held at: ``alpha`` split evenly over :attr:`families`
        (Bonferroni across families, Holm within each), so a whole run's verdicts raise a
        false alarm with probability at most ``alpha`` for any dependence between them."""
        return self.alpha / max(len(self.families), 1)

    @property
    def file_name(self) -> str:
        """The name as a safe file name (results/<file_name>.sqlite): letters, digits, '.', '_'
        and '-' only, never a path (``../../x`` becomes ``x``)."""
        return re.sub(r"[^A-Za-z0-9._-]+", "_", self.name).strip("._") or "suite"
