"""Stored measurements -> PNG figures (matplotlib, Agg, no pyplot state).

Two figures: per integrand (or scene), the error against the budget and against wall time
on log-log axes with each technique's fitted slope and its interval, a guide line at the
expected rate, and the efficiency ratios against the baseline as a forest plot; per sampler
check, heatmaps of the standardised chi-square residuals at both resolutions and the 1-D
marginals against their expectation.  Every panel states its uncertainty and sample count.
"""
from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import matplotlib
import matplotlib.ticker
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from reports.data import Results

matplotlib.use("Agg")

__all__ = ["Curve", "Ratio", "integrand_curves", "integrand_figure", "sampler_figure", "PARAM_LABELS"]

_STYLE = {"font.size": 8.5, "axes.titlesize": 9, "axes.labelsize": 8.5, "legend.fontsize": 8,
          "axes.spines.top": False, "axes.spines.right": False, "axes.grid": True, "grid.alpha": 0.25,
          "grid.linewidth": 0.5, "savefig.facecolor": "white", "figure.facecolor": "white"}
_DPI = 100
_MARKERS = "osD^v<>ph*XP"

# the equal-measure parameters s of harness.samplers.domains, per domain
PARAM_LABELS = {"interval": ("s = (x − a)/(b − a)",), "half_line": ("s = x/(1 + x)",), "square": ("x", "y"),
                "disk": ("s0 = r²", "s1 = φ/2π"), "hemisphere": ("s0 = cos θ", "s1 = φ/2π"),
                "sphere": ("s0 = (1 − cos θ)/2", "s1 = φ/2π")}


@dataclass(frozen=True)
class Curve:
    """One technique's error at several budgets, and its fitted log-log slope."""

    technique: str
    points: pd.DataFrame      # n, err, lo, hi (95 % interval), seconds, seconds_se, replicas
    slope: float
    slope_lo: float
    slope_hi: float
    expected: float
    verdict: str
    error: str                # what err is: "RMSE", "sqrt(relMSE)", ...


@dataclass(frozen=True)
class Ratio:
    technique: str
    value: float
    lo: float
    hi: float
    n: int
    baseline: str
    definition: str           # "1/(V·T)", "1/(relMSE T)", ...


@dataclass(frozen=True)
class Group:
    """What one integrand's (or scene's) figure shows."""

    curves: list[Curve]
    ratios: list[Ratio]
    render: bool              # budgets are samples per pixel, times per image
    common: str = ""          # settings every technique label shared, taken out of the labels


def _points(detail: dict[str, Any]) -> tuple[pd.DataFrame, str] | None:
    """Per-budget errors from a convergence row's detail: this harness's ``table`` (n, rmse,
    rmse_lo, rmse_hi, seconds, replicas) or lists ``budgets`` and ``rmse``/``relmse`` (with
    optional ``*_lo``/``*_hi``, ``seconds``, ``replicas``) as a renderer adapter may store."""
    if "table" in detail:
        t, name = dict(detail["table"]), "rmse"
    elif "budgets" in detail:
        name = next((k for k in ("rmse", "relmse", "error") if k in detail), None)
        if name is None:
            return None
        t = {k: v for k, v in detail.items() if isinstance(v, list)}
        t["n"] = detail["budgets"]
    else:
        return None
    df = pd.DataFrame({"n": t["n"], "err": t.get(name)})
    nan = [math.nan] * len(df)
    df["lo"] = t.get(f"{name}_lo", nan)
    df["hi"] = t.get(f"{name}_hi", nan)
    df["seconds"] = t.get("seconds", nan)
    df["seconds_se"] = t.get("seconds_se", nan)
    df["replicas"] = t.get("replicas", nan)
    label = (detail["error"] if isinstance(detail.get("error"), str)
             else {"rmse": "RMSE", "relmse": "relMSE"}.get(name, name))
    return df.astype(float), label


def _shorten(names: list[str]) -> tuple[dict[str, str], str]:
    """Labels made of "key=value, ..." lose the settings all of them share (returned joined)."""
    parts = {n: n.split(", ") for n in names}
    if len(names) < 2 or not all("=" in q for ps in parts.values() for q in ps):
        return {n: n for n in names}, ""
    shared = set.intersection(*(set(ps) for ps in parts.values()))
    short = {n: ", ".join(q for q in ps if q not in shared) or n for n, ps in parts.items()}
    if len(set(short.values())) < len(short):
        return {n: n for n in names}, ""
    return short, ", ".join(q for q in parts[names[0]] if q in shared)


def integrand_curves(results: Results) -> dict[tuple[str, str], Group]:
    """Per (suite, integrand): the convergence curves and efficiency ratios stored for it.
    A technique that appears twice (cases at different sample counts) is labelled with its n."""
    out: dict[tuple[str, str], Group] = {}
    cases = results.cases
    for (suite, integrand), g in cases.groupby(["suite", "integrand"], sort=False):
        curves, ratios = [], []
        twice = g.groupby("technique")["case_key"].nunique()
        short, common = _shorten(list(dict.fromkeys(g["technique"].astype(str))))
        for key, c in g.groupby("case_key", sort=False):
            rows = {r["measurement"]: r for r in c.to_dict("records")}
            tech = short[str(c["technique"].iloc[0])]
            if twice.get(c["technique"].iloc[0], 1) > 1:
                n = (rows.get("bias") or {}).get("n")
                tech += f" (n = {int(n):,})" if n == n and n is not None else f" ({key[:6]})"
            conv = rows.get("convergence_slope") or rows.get("convergence")
            got = _points(conv["detail"]) if conv is not None else None
            if got is not None:
                pts, error = got
                if pts["replicas"].isna().all() and conv["n"] == conv["n"] and conv["n"]:
                    pts["replicas"] = float(conv["n"]) / len(pts)   # n of the fit: replicas over all budgets
                evt = (rows.get("rmse") or {}).get("detail", {}).get("error_vs_time")
                if evt and len(evt.get("seconds", [])) == len(pts):  # timings of the error-vs-time units
                    pts["seconds"] = np.asarray(evt["seconds"], float)
                    pts["seconds_se"] = np.asarray(evt.get("seconds_se", [math.nan] * len(pts)), float)
                curves.append(Curve(tech, pts, conv["value"], conv["lo"], conv["hi"],
                                    float(conv["detail"].get("expected", -0.5)), str(conv["verdict"] or ""),
                                    error))
            eff = rows.get("efficiency_ratio") or (rows.get("efficiency") if "baseline" in
                                                   (rows.get("efficiency") or {}).get("detail", {}) else None)
            if eff is not None and all(v is not None and math.isfinite(v) for v in (eff["value"], eff["lo"],
                                                                                     eff["hi"])):
                base = str(eff["detail"].get("baseline", ""))
                ratios.append(Ratio(tech, eff["value"], eff["lo"], eff["hi"], int(eff["n"] or 0),
                                    short.get(base, base), str(eff["detail"].get("definition", "1/(V·T)"))))
        if curves or ratios:
            out[(suite, integrand)] = Group(curves, ratios, bool((g["kind"] == "render").any()), common)
    return out


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


def _colors(names: Sequence[str]) -> dict[str, Any]:
    cmap = matplotlib.colormaps["tab10" if len(names) <= 10 else "tab20"]
    return {t: cmap(i % cmap.N) for i, t in enumerate(names)}


def _common(values: Sequence[float]) -> str:
    vals = sorted({int(v) for v in values if v == v})
    return f"{vals[0]:,}" if len(vals) == 1 else (f"{vals[0]:,}–{vals[-1]:,}" if vals else "?")


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _decade(v: float, _pos: Any = None) -> str:
    """10⁻³ in plain Unicode: matplotlib's mathtext labels cost a fifth of a figure's time."""
    if not v > 0:
        return ""
    k = math.log10(v)
    return "10" + str(round(k)).translate(_SUPERSCRIPT) if abs(k - round(k)) < 1e-6 else _plain(v)


def _plain(v: float, _pos: Any = None) -> str:
    """A tick value as people write it: 500, 2000, 0.05, 5×10⁻⁶."""
    if not v > 0:
        return ""
    if 1e-3 <= v < 1e6:
        return np.format_float_positional(v, precision=3, unique=True, fractional=False, trim="-")
    k = math.floor(math.log10(v) + 1e-9)
    m = v / 10.0**k
    return ("" if abs(m - 1) < 1e-6 else f"{m:.2g}×") + "10" + str(k).translate(_SUPERSCRIPT)


def _log_ticks(ax) -> None:
    """Log axes: over two decades or more, decades only (minor ticks cost half a figure's
    drawing time and a grid of decades shows as much); over less, plain numbers at 1, 2, 5."""
    for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        if axis.get_scale() != "log" or not min(lim) > 0:
            continue
        if math.log10(max(lim) / min(lim)) >= 2:
            axis.set_minor_locator(matplotlib.ticker.NullLocator())
            axis.set_major_formatter(matplotlib.ticker.FuncFormatter(_decade))
        else:
            plain = matplotlib.ticker.FuncFormatter(_plain)
            axis.set_major_formatter(plain)
            axis.set_minor_locator(matplotlib.ticker.LogLocator(subs=(2.0, 5.0)))
            axis.set_minor_formatter(plain)


class _Layout:
    """Axes placed in inches on a figure of fixed width (faster than a layout engine)."""

    def __init__(self, width: float, height: float):
        self.fig = Figure(figsize=(width, height))
        self.w, self.h = width, height

    def axes(self, left: float, bottom: float, width: float, height: float, **kw):
        return self.fig.add_axes((left / self.w, bottom / self.h, width / self.w, height / self.h), **kw)


_WIDTH = 14.4          # inches at _DPI: about the width of the report's main column
_PLOT_H = 2.7          # height of a plot panel


def integrand_figure(group: Group) -> bytes:
    """Error vs budget, error vs wall time, and efficiency ratios, for one integrand: PNG."""
    curves, ratios = group.curves, group.ratios
    names = list(dict.fromkeys([c.technique for c in curves] + [r.technique for r in ratios]))
    color = _colors(names)
    ncol = 3
    legend_h = 0.19 * math.ceil(len(curves) / ncol) if curves else 0.0
    bottom = 0.5 + legend_h + (0.15 if curves else 0.0) + (0.16 if ratios else 0.0)
    height = bottom + _PLOT_H + 0.35
    label_w = min(0.05 * max((len(r.technique) for r in ratios), default=0) + 0.2, 2.8)
    unit = ("samples per pixel", "per image") if group.render else ("samples per estimate n", "per estimate")
    with matplotlib.rc_context(_STYLE):
        lay = _Layout(_WIDTH, height)
        if curves:
            split = 8.6 if ratios else _WIDTH - 0.3
            a_w = (split - 0.7 - 0.75) * 0.52
            _convergence_panel(lay.axes(0.7, bottom, a_w, _PLOT_H), curves, color, unit[0])
            _time_panel(lay.axes(0.7 + a_w + 0.75, bottom, split - 0.7 - a_w - 0.75, _PLOT_H), curves, color,
                        unit[1])
            lay.fig.legend(*_legend(curves, color), loc="lower left",
                           bbox_to_anchor=(0.5 / _WIDTH, 0.04 / height),
                           ncol=ncol, frameon=False, handlelength=2.0, columnspacing=1.8, borderaxespad=0)
        if ratios:
            left = (8.6 if curves else 0.3) + 0.3 + label_w
            _ratio_panel(lay.axes(left, bottom, _WIDTH - 0.3 - left, _PLOT_H), ratios, color)
        return _png(lay.fig)


def _legend(curves: list[Curve], color: dict[str, Any]) -> tuple[list, list[str]]:
    from matplotlib.lines import Line2D

    handles, labels = [], []
    for i, c in enumerate(curves):
        handles.append(Line2D([], [], color=color[c.technique], marker=_MARKERS[i % len(_MARKERS)],
                              markersize=4))
        if math.isfinite(c.slope):
            s = f"slope {c.slope:+.2f} [{c.slope_lo:+.2f}, {c.slope_hi:+.2f}]".replace("-", "−")
        else:
            s = "zero error" if not (c.points["err"] > 0).any() else "no slope"
        flag = "  (slower than expected)" if c.verdict == "slower than expected" else ""
        labels.append(f"{c.technique}: {s}{flag}")
    return handles, labels


def _convergence_panel(ax, curves: list[Curve], color: dict[str, Any], xlabel: str) -> None:
    drawn = []
    for i, c in enumerate(curves):
        p = c.points[(c.points["err"] > 0) & np.isfinite(c.points["err"])]
        if p.empty:
            continue
        col, mk = color[c.technique], _MARKERS[i % len(_MARKERS)]
        yerr = np.vstack([p["err"] - p["lo"], p["hi"] - p["err"]])
        ax.errorbar(p["n"], p["err"], yerr=np.where(np.isfinite(yerr), yerr, 0), fmt=mk, color=col,
                    markersize=3.5, capsize=2, elinewidth=0.8, lw=0)
        if math.isfinite(c.slope) and len(p) >= 2:
            # the least-squares line passes through the mean of log n and log error
            x0, y0 = np.mean(np.log(p["n"])), np.mean(np.log(p["err"]))
            xs = np.array([p["n"].min(), p["n"].max()])
            ax.plot(xs, np.exp(y0 + c.slope * (np.log(xs) - x0)), color=col, lw=1.1)
        drawn.append(p)
    if drawn:  # expected-rate guides, one per expected slope, above the first drawn curve
        first = drawn[0]
        for e in sorted({c.expected for c in curves if math.isfinite(c.expected)}):
            x0, y0 = np.mean(np.log(first["n"])), np.mean(np.log(first["err"])) + math.log(3)
            xs = np.array([min(d["n"].min() for d in drawn), max(d["n"].max() for d in drawn)])
            ax.plot(xs, np.exp(y0 + e * (np.log(xs) - x0)), color="0.35", lw=1, ls=(0, (4, 3)))
            ax.annotate(f"expected rate, slope {e:+g}".replace("-", "−"),
                        (xs[0], np.exp(y0 + e * (np.log(xs[0]) - x0))),
                        xytext=(2, 4), textcoords="offset points", ha="left", va="bottom", fontsize=7.5,
                        color="0.3")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    error = curves[0].error
    ax.set_ylabel(error)
    reps = _common([r for c in curves for r in c.points["replicas"]])
    ax.set_title(f"Convergence: {error}, 95% CI over {reps} replicas per point", loc="left")
    _log_ticks(ax)


def _time_panel(ax, curves: list[Curve], color: dict[str, Any], per: str) -> None:
    for i, c in enumerate(curves):
        p = c.points[(c.points["err"] > 0) & np.isfinite(c.points["err"]) & (c.points["seconds"] > 0)]
        if p.empty:
            continue
        yerr = np.vstack([p["err"] - p["lo"], p["hi"] - p["err"]])
        xerr = 1.96 * p["seconds_se"].to_numpy()
        ax.errorbar(p["seconds"], p["err"], yerr=np.where(np.isfinite(yerr), yerr, 0),
                    xerr=np.where(np.isfinite(xerr), xerr, 0), fmt=_MARKERS[i % len(_MARKERS)] + "-",
                    color=color[c.technique], markersize=3.5, capsize=2, elinewidth=0.8, lw=0.9)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"wall time {per} [s], 95% CI")
    ax.set_ylabel(curves[0].error)
    ax.set_title("Error against run time (lower left is better)", loc="left")
    _log_ticks(ax)


def _ratio_panel(ax, ratios: list[Ratio], color: dict[str, Any]) -> None:
    y = np.arange(len(ratios))[::-1]
    for yi, r in zip(y, ratios):
        lo = r.value - r.lo if math.isfinite(r.lo) else 0
        hi = r.hi - r.value if math.isfinite(r.hi) else 0
        ax.errorbar([r.value], [yi], xerr=[[max(lo, 0)], [max(hi, 0)]], fmt="o", color=color[r.technique],
                    markersize=4, capsize=2.5, elinewidth=1)
    ax.axvline(1.0, color="0.35", lw=0.9, ls=(0, (4, 3)))
    ax.set_yticks(y, [r.technique for r in ratios])
    ax.set_xscale("log")
    ax.grid(axis="y", visible=False)
    base = ", ".join(sorted({r.baseline for r in ratios if r.baseline})) or "the baseline"
    definition = ", ".join(sorted({r.definition for r in ratios}))
    ax.set_xlabel(f"{definition} relative to {base}\n(n = {_common([r.n for r in ratios])} samples each)")
    ax.set_title("Efficiency ratio, 95% CI (right is better)", loc="left")
    ax.tick_params(axis="y", labelsize=7.5)
    _log_ticks(ax)


# --- sampler checks ------------------------------------------------------------------------------
def _test(tests: list[dict[str, Any]], prefix: str) -> dict[str, Any] | None:
    return next((t for t in tests if str(t.get("test", "")).startswith(prefix)), None)


def _stat_text(t: dict[str, Any] | None) -> str:
    if t is None:
        return ""
    return f"χ² = {t['statistic']:.1f}, df = {int(t['df'])}, p = {t['pvalue']:.2g}"


def sampler_figure(domain: str, detail: dict[str, Any], n: int) -> bytes | None:
    """Residual heatmaps (or bars on an interval) and marginals of one chi-square check: PNG,
    or None when the check stored no residuals (runs before they were kept)."""
    res = {k: np.asarray(v, float) for k, v in (detail.get("residuals") or {}).items()}
    marg = detail.get("marginals") or {}
    if not res:
        return None
    tests = detail.get("tests", [])
    labels = PARAM_LABELS.get(domain, ("s0", "s1"))
    two_d = next(iter(res.values())).ndim == 2
    bottom, plot_h, height = 0.75, 2.55, 4.0
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.8")
    with matplotlib.rc_context(_STYLE):
        lay = _Layout(_WIDTH, height)
        image = None
        for i, g in enumerate(g for g in ("coarse", "fine") if g in res):
            r = res[g]
            ax = lay.axes(0.65 + i * 3.55, bottom, 3.0, plot_h)
            shape = "x".join(map(str, r.shape))
            if two_d:
                image = ax.imshow(r, origin="lower", extent=(0, 1, 0, 1), aspect="auto", cmap=cmap, vmin=-4,
                                  vmax=4, interpolation="nearest")
                ax.set_xlabel(labels[1] if len(labels) > 1 else "s1")
                ax.set_ylabel(labels[0])
                ax.grid(False)
            else:
                edges = np.linspace(0, 1, r.size + 1)
                r = np.nan_to_num(r, nan=0.0)
                ax.stairs(np.clip(r, 0, 6), edges, fill=True, color="#b2182b", lw=0)
                ax.stairs(np.clip(r, -6, 0), edges, fill=True, color="#2166ac", lw=0)
                for h in (-3, 3):
                    ax.axhline(h, color="0.4", lw=0.7, ls=(0, (3, 3)))
                ax.set_ylim(-6, 6)
                ax.set_xlim(0, 1)
                ax.set_xlabel(labels[0])
                ax.set_ylabel("(observed − expected)/σ")
            if np.isnan(res[g]).all():
                ax.text(0.5, 0.5, "every cell pooled:\nexpectation < 5 per cell", ha="center", va="center",
                        transform=ax.transAxes, fontsize=8, color="0.3")
            ax.set_title(f"{g} grid {shape.replace('x', '×')}\n"
                         f"{_stat_text(_test(tests, f'chi-square {shape}'))}",
                         loc="left", fontsize=8)
        if image is not None:
            cax = lay.axes(7.25, bottom, 0.12, plot_h)
            lay.fig.colorbar(image, cax=cax, extend="both").set_label("(o − e)/σ per cell", labelpad=1)
        x0 = 8.75
        width = (_WIDTH - 0.25 - x0 - 0.7 * (len(marg) - 1)) / max(len(marg), 1)
        for j, (axis, m) in enumerate(sorted(marg.items())):
            _marginal(lay, x0 + j * (width + 0.7), bottom, width, plot_h, axis, m, labels, tests)
        lay.fig.text(0.65 / _WIDTH, 0.06 / height, f"n = {n:,} samples.  Residuals (o − e)/σ per cell, "
                     "colour clipped at ±4; grey (or 0): cells with expectation < 5, pooled in the "
                     "statistic.  s: the domain's equal-measure coordinates.",
                     fontsize=7.5, color="0.35")
        return _png(lay.fig)


def _marginal(lay: _Layout, left: float, bottom: float, width: float, height: float, axis: str,
              m: dict[str, list[float]], labels: tuple[str, ...], tests: list[dict[str, Any]]) -> None:
    obs, exp = np.asarray(m["observed"], float), np.asarray(m["expected"], float)
    bins = obs.size
    dens = bins / max(exp.sum(), 1.0)
    edges = np.linspace(0, 1, bins + 1)
    low_h = 0.26 * height
    top = lay.axes(left, bottom + low_h + 0.08, width, height - low_h - 0.08)
    low = lay.axes(left, bottom, width, low_h, sharex=top)
    band = np.where(exp >= 5, 2 * np.sqrt(np.maximum(exp, 0)) * dens, 0.0)
    top.stairs((exp * dens) + band, edges, baseline=(exp * dens) - band, fill=True, color="0.78", lw=0,
               label="±2σ (expectation ≥ 5)")
    top.stairs(exp * dens, edges, color="0.2", lw=1.0, label="expected (cubature)")
    top.plot((edges[:-1] + edges[1:]) / 2, obs * dens, ".", color="#d6604d", ms=2.6, label="observed")
    positive = exp[exp > 0] * dens
    if positive.size and positive.max() / max(positive.min(), 1e-300) > 100:
        top.set_yscale("log")
        _log_ticks(top)
    top.set_ylabel("density")
    top.legend(loc="best", frameon=False, fontsize=7)
    cvm = _test(tests, f"Cramer-von Mises u{axis[1:]}")
    label = ("" if cvm is None else
             f"Cramér–von Mises on u{axis[1:]}: W² = {cvm['statistic']:.3g}, p = {cvm['pvalue']:.2g}")
    top.set_title(f"marginal {axis} ({bins} bins shown)\n{label}", loc="left", fontsize=8)
    top.tick_params(labelbottom=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.clip(np.where(exp >= 5, (obs - exp) / np.sqrt(exp), 0.0), -5, 5)
    low.stairs(np.maximum(z, 0), edges, fill=True, color="#b2182b", lw=0)
    low.stairs(np.minimum(z, 0), edges, fill=True, color="#2166ac", lw=0)
    low.set_ylim(-5, 5)
    low.set_yticks([-3, 0, 3])
    low.set_ylabel("(o−e)/σ")
    k = int(axis[1:])
    low.set_xlabel(labels[k] if k < len(labels) else axis)
    low.set_xlim(0, 1)


def pvalue_histogram(counts: Sequence[int], scale: str) -> bytes:
    """Histogram of a multi-scale test's tested tile-channel p-values at one scale, as counts
    in 20 equal bins of [0, 1], with the flat line H0 predicts: a test that holds its level is
    flat; a peak at 0 is a bias (or a miscalibration) spread over many tiles, a peak at 1 a
    conservative test."""
    c = np.asarray(counts, dtype=np.float64)
    edges = np.linspace(0, 1, c.size + 1)
    fig = Figure(figsize=(4.2, 2.6))
    ax = fig.add_subplot()
    ax.bar(edges[:-1], c, width=np.diff(edges), align="edge", color="#6e7781")
    ax.axhline(c.sum() / max(c.size, 1), color="#cf222e", lw=1, label="uniform (H0)")
    ax.set_xlabel(f"p-value ({scale}, {int(c.sum())} tested)")
    ax.set_ylabel("count")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    return _png(fig)
