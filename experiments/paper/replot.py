"""Redraw the paper studies' figures (docs/figures/paper_<scene>_{convergence,
iterations,work_precision}.png) from the committed results, without rerunning
the studies (which take minutes to tens of minutes each).

    python experiments/paper/replot.py [docs/results/paper_bar ...]

Without arguments, every docs/results/paper_*/ with a study.csv and claims.json.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from _paper import RESULTS, replot


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="*", type=Path,
                        help="results folders (default: docs/results/paper_*)")
    args = parser.parse_args()
    folders = args.results or sorted(p.parent for p in RESULTS.glob("paper_*/study.csv"))
    for folder in folders:
        for path in replot(folder):
            print(f"{folder} -> {path}")


if __name__ == "__main__":
    main()
