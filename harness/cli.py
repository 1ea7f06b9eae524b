"""Command line: ``harness run SUITE``, ``harness report``, ``harness show --db PATH``, \
``harness gc --db PATH``, ``harness compare``, ``harness check-sampler`` and ``harness list``."""
from __future__ import annotations

import argparse
import os
import signal
import sys

from tqdm import tqdm

import reference_estimators as rest

from harness.adapters.base import RenderError
from harness.suite.execute import ClusterError
from harness.suite.parse import SuiteError, load_suite
from harness.suite.readers import load, plan_progress, runs
from harness.suite.run import run_suite
from harness.suite.store import StoreError
from harness.usercode import UserCodeError


def _seconds(text: str) -> float:
    """A time in seconds for argparse: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}")
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="harness", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a suite file and print the table of estimates")
    run.add_argument("suite", help="suite file (TOML), e.g. suites/default.toml")
    run.add_argument("--threads", type=int, default=None,
                     help="threads (default: the suite's, else all cores)")
    run.add_argument("--csv", metavar="PATH", help="also write the table as CSV")
    run.add_argument("--db", metavar="PATH", help="results database (default: results/<suite name>.sqlite)")
    run.add_argument("--dask", metavar="ADDRESS",
                     help="run on a Dask scheduler at ADDRESS, or 'local' for a LocalCluster")
    run.add_argument("--wait", type=_seconds, default=60, metavar="SECONDS",
                     help="how long to wait for a lock another process holds on the database (default 60)")
    show = sub.add_parser("show", help="print the measurements stored in a results database (each suite's "
                                       "latest finished run)")
    show.add_argument("--db", metavar="PATH", required=True)
    show.add_argument("--suite", help="only this suite")
    which = show.add_mutually_exclusive_group()
    which.add_argument("--run", type=int, metavar="N", help="the measurements of run N (see --runs)")
    which.add_argument("--all", action="store_true", help="every run's measurements, with their run")
    which.add_argument("--runs", action="store_true", help="list the runs: suite file, revision, times")
    rep = sub.add_parser("report",
                         help="write the stored results as one self-contained HTML page (or CSV, Markdown)")
    rep.add_argument("--db", metavar="PATH", default="results/default.sqlite",
                     help="results database (default: results/default.sqlite)")
    rep.add_argument("-o", "--output", metavar="PATH", help="output file (default: the database path with "
                                                           ".html, .csv or .md)")
    rep.add_argument("--format", choices=["html", "csv", "markdown"], default="html")
    rep.add_argument("--suite", help="only this suite")
    rep.add_argument("--run", type=int, metavar="N", help="run N instead of each suite's latest "
                                                         "(harness show --runs lists them)")
    gc = sub.add_parser("gc", help="remove stored units, images and cached references no suite's latest run "
                                   "needs; --repair a damaged database")
    gc.add_argument("--db", metavar="PATH", required=True)
    gc.add_argument("--dry-run", action="store_true", help="count what would be removed, change nothing")
    gc.add_argument("--repair", action="store_true",
                    help="move a damaged database aside and copy every readable row into a new one")
    sub.add_parser("list", help="list the catalogue's integrands, techniques and samplers")
    cmp = sub.add_parser("compare", help="two renderers' replica renders against each other, no "
                                         "reference needed (Welch tests per pixel, per 2 to 16 pixel tile "
                                         "and on the image mean; relMSE and FLIP maps)")
    cmp.add_argument("a", help="a folder of replica images (EXR, PFM, HDR), or with --db a render case (key "
                               "prefix or part of scene/configuration)")
    cmp.add_argument("b", help="the same for the other renderer")
    cmp.add_argument("--db", metavar="PATH", help="results database holding both render cases")
    cmp.add_argument("-o", "--output", metavar="PATH", default="compare.html", help="the report page")
    cmp.add_argument("--alpha", type=float, default=0.01)
    cmp.add_argument("--spp", type=int, help="samples per pixel of a replica (the fewer of the two), if "
                                             "known: scales whose tiles average fewer than 64 samples are "
                                             "not tested")
    chk = sub.add_parser("check-sampler", help="test a sampler against its pdf (chi-square and friends)")
    chk.add_argument("target", help="module:attribute or path/to/file.py:attribute (found from the current "
                                    "directory): an object with sample(u) and pdf(x), or a function "
                                    "returning one (or a (sample, pdf[, domain]) tuple)")
    chk.add_argument("--domain",
                     help="interval, square, disk, hemisphere, sphere (unless the target gives one)")
    chk.add_argument("--samples", type=int, default=1_000_000)
    chk.add_argument("--seed", type=int, default=0)
    chk.add_argument("--alpha", type=float, default=0.01)
    chk.add_argument("--total", type=float, default=None,
                     help="the pdf's integral where some u give no sample (NaN rows); default: the sampler's "
                          "own total, else from the cubature")
    chk.add_argument("--mcmc", action="store_true", help="also run the emcee cross-check")
    args = parser.parse_args(argv)

    if args.command == "list":
        return _list()
    if args.command == "show":
        return _show(args)
    if args.command == "report":
        return _report(args.db, args.output, args.format, args.suite, args.run)
    if args.command == "gc":
        return _gc(args)
    if args.command == "check-sampler":
        return _check_sampler(args)
    if args.command == "compare":
        return _compare(args)
    try:
        suite = load_suite(args.suite)
    except SuiteError as e:
        print(f"harness: {e}", file=sys.stderr)
        return 2
    if args.threads is not None and args.threads < 1:
        print("harness: --threads must be >= 1", file=sys.stderr)
        return 2
    if args.csv and (why := _unwritable(args.csv, "--csv")):
        print(f"harness: {why}", file=sys.stderr)
        return 2
    db = args.db or f"results/{suite.file_name}.sqlite"
    return _run(suite, db, args.threads, args.csv, args.dask, args.wait)


def _unwritable(path: str, flag: str) -> str | None:
    """Why ``path`` (given to ``flag``) cannot name an output file (a folder; a missing
    folder), or None; checked before the work, so that a run does not end on it."""
    from pathlib import Path

    p = Path(path)
    if p.is_dir():
        return f"{flag} {path}: a folder; give a file name"
    if not p.resolve().parent.is_dir():
        return f"{flag} {path}: no folder {p.parent}"
    return None


def _run(suite, db: str, threads: int | None, csv: str | None, dask: str | None, wait: float) -> int:
    bar = tqdm(total=0, unit="unit", desc=f"{suite.name}", disable=not sys.stderr.isatty(), leave=False)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    def stored() -> str:  # counted in the database: exact whenever the signal came
        done, total = plan_progress(db, suite.name)
        return f"{done} of {total} units stored in {db}"

    try:
        summary = run_suite(suite, db, threads=threads, dask=dask, progress=progress, wait=wait)
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: say what is kept (entry() prints it)
        raise type(e)(f"{stored()}, rerun to resume") from None
    except (RenderError, UserCodeError) as e:  # a render or a user's callable failed: nothing stored for it
        print(f"harness: {e}\nharness: {stored()}; fix it and rerun to resume", file=sys.stderr)
        return 2
    except (StoreError, ClusterError) as e:  # the database, the disk or the cluster: one line naming it
        print(f"harness: {e}", file=sys.stderr)
        return 2
    finally:
        bar.close()
    what = ", ".join(f"{len(o.names)} {o.noun}" for o in summary.outcomes if o.names)
    families = suite.families
    split = (f"{suite.family_alpha:.3g} for each of {len(families)} families ({', '.join(families)}), Holm "
             "within each" if len(families) > 1 else "Holm")
    sizes = (f"; {suite.batches} batches per bias test, {suite.replicas} replicas per budget" if suite.cases
             else "")
    print(f"suite {suite.name!r} ({suite.path}): {what}; seed {suite.seed}; false-alarm rate of the whole "
          f"run alpha {suite.alpha:g} ({split}){sizes}")
    print("\n\n".join(o.text for o in summary.outcomes if o.text))
    print(f"\n{what} in {summary.seconds:.1f} s: {summary.units_run} of {summary.units_planned} work units "
          f"computed, the rest read from {summary.db}.")
    xfailed = 0
    for o in summary.outcomes:
        for i, name in enumerate(o.names):
            if o.status(i) == "xfailed":
                print(f"  XFAIL {name}: {o.xfail[i]}")
            elif o.problem(i):
                print(f"  FAILED {name}: " + o.problem(i).replace("\n", "\n    "))
        xfailed += o.xfailed
    print(f"summary: {summary.cases - summary.failed - xfailed} passed, {summary.failed} failed"
          + (f", {xfailed} xfailed" if xfailed else ""))
    if csv:
        import pandas as pd  # deferred, as in kind.Outcome.frame
        frames = [o.frame.assign(kind=o.kind) for o in summary.outcomes if o.table]
        try:
            (pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()).to_csv(csv, index=False)
        except OSError as e:   # its folder went, or no permission: the results are stored all the same
            print(f"harness: --csv {csv}: {e.strerror or e}; the results are stored in {db}", file=sys.stderr)
            return 2
        print(f"table written to {csv}")
    return 1 if summary.failed else 0


def _check_sampler(args) -> int:
    from pathlib import Path

    from harness.samplers import check_sampler, mcmc_crosscheck
    from harness.samplers.user import resolve_sampler
    from harness.usercode import UserCodeError, load_attr

    try:
        user = resolve_sampler(load_attr(args.target, base=Path.cwd()), name=args.target)
    except UserCodeError as e:
        print(f"harness: cannot load {e}", file=sys.stderr)
        return 2
    domain = args.domain or user.domain
    if domain is None:
        print("harness: say --domain (interval, square, disk, hemisphere, sphere)", file=sys.stderr)
        return 2
    total = args.total if args.total is not None else user.total
    try:    # the sampler's own pole and breaks, if it has them (harness.samplers.user)
        result = check_sampler(user.sample, user.pdf, user.check_domain(domain), sample_count=args.samples,
                               seed=args.seed, alpha=args.alpha, udim=user.udim, total=total,
                               breaks=user.breaks)
    except ValueError as e:  # a bad argument, or the user's code failing (UserCodeError names it)
        print(f"harness: {e}", file=sys.stderr)
        return 2
    print(f"{args.target} on the {domain}:")
    print(result)
    ok = result.passed
    if args.mcmc:
        try:
            m = mcmc_crosscheck(user.sample, user.pdf, user.check_domain(domain), seed=args.seed,
                                alpha=args.alpha, udim=user.udim)
        except ValueError as e:  # the user's code failing (UserCodeError names it)
            print(f"harness: {e}", file=sys.stderr)
            return 2
        print("\nMCMC cross-check (emcee):")
        print(m)
        ok = ok and m.verdict != "failed"  # inconclusive (chain too short) fails nothing
    print(f"summary: {int(ok)} passed, {int(not ok)} failed")
    return 0 if ok else 1


def _compare(args) -> int:
    from pathlib import Path

    from harness.stats.compare import compare_images
    from reports.compare import compare_page, load_pair

    if why := _unwritable(args.output, "-o"):
        print(f"harness: {why}", file=sys.stderr)
        return 2
    try:
        a, b = load_pair(args.a, args.b, db=args.db)
        result = compare_images(a.images, b.images, alpha=args.alpha, spp=args.spp)
    except ValueError as e:
        print(f"harness: {e}", file=sys.stderr)
        return 2
    out = Path(args.output)
    try:
        out.write_text(compare_page(a, b, result), encoding="utf-8")
    except OSError as e:
        print(f"harness: -o {out}: {e.strerror or e}", file=sys.stderr)
        return 2
    for name, s in (("A", a), ("B", b)):
        print(f"{name}: {s.label} ({s.images.shape[0]} replicas, {s.source})")
    print(f"{result}\nreport: {out}")
    print(f"summary: {int(result.passed)} passed, {int(not result.passed)} failed")
    return 0 if result.passed else 1


def _report(db: str, output: str | None, fmt: str, suite: str | None, run: int | None) -> int:
    from reports import write_report

    try:
        path = write_report(db, output, fmt=fmt, suite=suite, run=run)
    except (FileNotFoundError, ValueError) as e:
        print(f"harness: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # the report file cannot be written
        print(f"harness: {e.filename or output}: {e.strerror or e}", file=sys.stderr)
        return 2
    print(f"report written to {path.resolve()}")
    return 0


def _show(args) -> int:
    try:
        df = runs(args.db) if args.runs else load(args.db, args.suite, run=args.run, all_runs=args.all)
    except (FileNotFoundError, ValueError) as e:
        print(f"harness: {e}", file=sys.stderr)
        return 2
    if df.empty:
        print(f"no {'runs' if args.runs else 'measurements'} in {args.db}")
        return 0
    if args.runs:
        cols = ["run", "suite", "file", "revision", "started", "finished", "units_planned", "units_run",
                "measurements"]
        print(df[cols].to_string(index=False))
        return 0
    cols = (["run"] if args.all else []) + ["suite", "integrand", "technique", "measurement", "value", "lo",
                                            "hi", "n", "pvalue", "alpha", "verdict"]
    print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.6g}"))
    if df["measurement"].isin(["log10_efficiency", "log10_efficiency_clock"]).any():
        print("log10_efficiency: 1/(V·T), T in seconds, its 95 % interval of that run's machine state only "
              "(other runs differ by more); log10_efficiency_clock: T in ticks of the reference clock timed "
              "beside each replica, its interval meant to hold across runs (harness.stats.timing.CLOCK; "
              "measured to on a loaded machine, not on an idle one: README)")
    return 0


def _gc(args) -> int:
    from harness.suite.gc import collect_garbage, repair

    try:
        print(repair(args.db) if args.repair else collect_garbage(args.db, dry_run=args.dry_run))
    except StoreError as e:
        print(f"harness: {e}", file=sys.stderr)
        return 2
    return 0


def _list() -> int:
    print("integrands (exact reference; techniques):")
    for f in rest.catalogue():
        print(f"  {f.name:<14} {f.domain:<10} d={f.dim:<3} I={f.reference:<24.17g} "
              f"{', '.join(rest.techniques(f))}")
        print(f"  {'':<14} {f.description}")
    print("\nsamplers:")
    for s in rest.samplers():
        params = ", ".join(f"{k}={v:g}" for k, v in s["params"].items())
        print(f"  {s['name']:<22} {s['method']:<9} {s['domain']:<10} {s['description']} ({params})")
    return 0


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C's KeyboardInterrupt."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


def entry() -> None:
    """Console-script entry: main(), quiet when the reader of stdout goes away (| head); Ctrl-C
    and SIGTERM end with one line (what was stored, how to resume) and exit 130 / 143."""
    signal.signal(signal.SIGTERM, _terminate)
    try:
        code = main()
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 1
    except KeyboardInterrupt as e:
        print(f"harness: interrupted{': ' + str(e) if str(e) else ''}", file=sys.stderr)
        code = 143 if isinstance(e, Terminated) else 130
    sys.exit(code)


if __name__ == "__main__":
    entry()
