"""A team's own sampler as the checks take it, from whatever shape the team wrote it in.

Accepted (``resolve_sampler``): an object with ``sample(u)`` and ``pdf(x)`` methods and,
optionally, ``domain`` (a domain name), ``total`` (the integral of its pdf where some u give
no sample), ``udim`` (uniforms per sample, up to 1024), ``breaks`` (where its pdf steps or
kinks, per parameter axis: check_sampler's) and ``pole`` (the sphere's: "x", "y" or "z";
None: "z"); a tuple ``(sample, pdf)`` or ``(sample, pdf, domain)``; or a factory returning
either (a class, or a callable without ``sample``), called with ``params``
(``GGX(alpha=0.3)``).
"""
from __future__ import annotations

import inspect
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from harness.samplers.calls import MAX_UDIM
from harness.samplers.domains import Domain
from harness.usercode import USER_ERRORS, UserCodeError, raised

__all__ = ["UserSampler", "resolve_sampler"]


@dataclass(frozen=True)
class UserSampler:
    """The parts check_sampler needs; None where the sampler does not say (the caller's
    settings or the domain's defaults apply)."""

    name: str
    sample: Callable[[Any], Any]
    pdf: Callable[[Any], Any]
    domain: str | None = None
    total: float | None = None
    udim: int | None = None
    breaks: Any = None
    pole: str = "z"

    def check_domain(self, domain: str) -> Domain:
        """The domain ``domain`` (the sampler's or the suite's name) with this sampler's pole."""
        return Domain(domain, pole=self.pole)


def resolve_sampler(obj: Any, params: dict[str, Any] | None = None, *, name: str) -> UserSampler:
    """The sampler ``obj`` is (see the module docstring); ``name`` (its module:attr) names it
    in every error.  A factory is called with ``params`` (none: called without arguments
    when ``obj`` has no ``sample`` of its own)."""
    if params or isinstance(obj, type) or (callable(obj) and _attribute(obj, "sample", name) is None):
        if not callable(obj):
            raise UserCodeError(f"{name}: params were given, but it is a {type(obj).__name__}, not a factory")
        try:
            obj = obj(**(params or {}))
        except USER_ERRORS as e:
            given = ", ".join(f"{k}={v!r}" for k, v in (params or {}).items())
            raise UserCodeError(f"{name}({given}) {raised(e)}") from e
    if isinstance(obj, tuple):
        if len(obj) not in (2, 3):
            raise UserCodeError(f"{name}: expected a (sample, pdf) or (sample, pdf, domain) tuple, got "
                                f"{len(obj)} items")
        sample, pdf, domain, total, udim = obj[0], obj[1], obj[2] if len(obj) == 3 else None, None, None
        breaks, pole = None, "z"
    else:
        keys = ("sample", "pdf", "domain", "total", "udim", "breaks", "pole")
        sample, pdf, domain, total, udim, breaks, pole = (_attribute(obj, key, name) for key in keys)
        pole = "z" if pole is None else pole
    if not (callable(sample) and callable(pdf)):
        raise UserCodeError(f"{name}: expected an object with sample(u) and pdf(x) methods, a (sample, pdf) "
                            f"tuple or a factory of one, got a {type(obj).__name__}")
    if domain is not None and not isinstance(domain, str):
        raise UserCodeError(f"{name}: 'domain' must be a domain name, got {domain!r}")
    if total is not None and (isinstance(total, bool) or not isinstance(total, numbers.Real)
                              or not 0 < total <= 1):
        raise UserCodeError(f"{name}: 'total' must be the pdf's integral, in (0, 1], got {total!r}")
    if udim is not None and (isinstance(udim, bool) or not isinstance(udim, numbers.Integral)
                             or not 1 <= udim <= MAX_UDIM):
        raise UserCodeError(f"{name}: 'udim' must be an integer from 1 to {MAX_UDIM}, got {udim!r}")
    try:    # the pole as Domain takes it (which domain it is for, the suite or the caller checks)
        Domain("sphere", pole=pole)
    except ValueError as e:
        raise UserCodeError(f"{name}: {e}") from None
    return UserSampler(name, sample, pdf, domain, None if total is None else float(total),
                       None if udim is None else int(udim), breaks, pole)


def _attribute(obj: Any, key: str, name: str) -> Any:
    """``obj.key``, None where it has none.  An attribute it has (found without running it)
    whose property raises, AttributeError included, or calls sys.exit is a UserCodeError
    naming it: a property's AttributeError had read as "no such attribute" (a total of None),
    its sys.exit had ended the harness."""
    try:
        inspect.getattr_static(obj, key)
        has = True
    except AttributeError:   # none, or one __getattr__ makes: as getattr finds it
        has = False
    try:
        return getattr(obj, key) if has else getattr(obj, key, None)
    except USER_ERRORS as e:
        raise UserCodeError(f"{name}.{key} {raised(e)}") from e
