"""False-alarm rate and power of harness.stats.check_unbiased on the calibration zoo.

    .venv/bin/python benchmarks/unbiased_calibration.py [--seeds 200] [--samples 1e5]

Prints, per estimator of harness.stats.zoo.zoo(), how often each verdict came out over the
seeds: for correct estimators the rate of "biased" is the false-alarm rate (alpha = 0.01), for
wrong ones it is the power.  The subtle faults are measured again at 10x the samples.
"""
from __future__ import annotations

import argparse
import time

from harness.stats import zoo as calibration

COLUMNS = ["estimator", "fault", "runs", "biased", "inconclusive", "consistent", "rate", "rate_lo", "rate_hi"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=200)
    parser.add_argument("--samples", default="1e5")
    args = parser.parse_args()
    n = int(float(args.samples))
    start = time.perf_counter()
    table = calibration.measure(calibration.zoo(), range(args.seeds), n)
    print(f"check_unbiased, alpha = 0.01, n = {n:.0e}, seeds 0..{args.seeds - 1} "
          f"({time.perf_counter() - start:.0f} s)\n")
    for title, rows in (("correct estimators (rate = false-alarm rate)", table[table["fault"] == "-"]),
                        ("wrong estimators (rate = power)", table[table["fault"] != "-"])):
        print(title)
        print(rows[COLUMNS].to_string(index=False, float_format=lambda v: f"{v:.3f}"), "\n")
    subtle_names = ("roulette(q=0.999) without 1/q", "uniform clamped at 0.99", "singularity/uniform x 1.01")
    subtle = [e for e in calibration.zoo() if e.name in subtle_names]
    table = calibration.measure(subtle, range(min(args.seeds, 100)), 10 * n)
    print(f"subtle faults at n = {10 * n:.0e}")
    print(table[COLUMNS].to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
