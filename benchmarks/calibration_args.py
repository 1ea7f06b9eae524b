"""The command line the image calibration benchmarks share (pixel_calibration.py,
render_calibration.py): seeds, replica counts and a filter on the cases' names."""
from __future__ import annotations

import argparse


def parser(doc: str, seeds: int) -> argparse.ArgumentParser:
    """--seeds (default ``seeds``), --replicas (4 8 16) and --only (substrings of case names)."""
    p = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, default=seeds)
    p.add_argument("--replicas", type=int, nargs="+", default=[4, 8, 16])
    p.add_argument("--only", nargs="*", default=[], help="substrings of the cases' names")
    return p
