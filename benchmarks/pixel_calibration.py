"""False-alarm rate and power of the multi-scale render bias test
(harness.stats.images.pixel_bias_test) on the image calibration zoo, side by side with the
peer on the same images: a t test per pixel-channel (Welch against a rendered reference's
parts), Bonferroni over all of them (Welch per pixel, as in Jung et al. 2020).

    .venv/bin/python benchmarks/pixel_calibration.py [--seeds 200] [--replicas 4 8 16]
                                                     [--only poisson compound]

Prints, per replica count, for each null of harness.stats.image_zoo.nulls() (rate = false-alarm
rate; alpha = 0.01, 2 of 200 expected, more than 6 beyond the binomial 0.99 quantile) and each
planted bias of faults() (rate = power), the verdict counts over the seeds, the rate with its
95 % Clopper-Pearson interval, the scales that rejected, and the peer's rejections; from 8
replicas on, the bias each scale detects with 80 % power (image_zoo.detectable).  About 20 ms
per case and seed on one core.
"""
from __future__ import annotations

import platform
import time

import calibration_args

from harness.stats import image_zoo

COLUMNS = ["case", "fault", "runs", "biased", "inconclusive", "consistent", "invalid", "rate", "rate_lo",
           "rate_hi", "peer", "rejecting scales"]


def main() -> None:
    args = calibration_args.parser(__doc__, 200).parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}; images "
          f"{image_zoo.SHAPE}, alpha = 0.01, seeds 0..{args.seeds - 1}")
    wanted = [c for c in image_zoo.nulls() + image_zoo.faults()
              if not args.only or any(s in c.name for s in args.only)]
    for r in args.replicas:
        start = time.perf_counter()
        table = image_zoo.measure(wanted, range(args.seeds), r, peer=True)
        print(f"\n{r} replicas ({time.perf_counter() - start:.0f} s)")
        for title, rows in (("unbiased renders (rate = false-alarm rate)", table[table["fault"] == "-"]),
                            ("planted biases (rate = power)", table[table["fault"] != "-"])):
            print(title)
            print(rows[COLUMNS].to_string(index=False, float_format=lambda v: f"{v:.3f}"), "\n")
        if r >= 8:   # the fine scales exist from 8 replicas on
            start = time.perf_counter()
            power = image_zoo.detectable(r, seeds=range(min(args.seeds, 100)))
            print(f"detectable bias at 80 % power: one aligned square of 'size' pixels k tile-SE too bright "
                  f"(normal pixels, {min(args.seeds, 100)} seeds; {time.perf_counter() - start:.0f} s)")
            print(power.to_string(index=False), "\n")


if __name__ == "__main__":
    main()
