"""Fit accuracy against the disc budget, and ``compare`` on a 24-MP photo: a thin wrapper over bokehfit.bench.

Usage::

    python benchmarks/compare_speed.py [--quick] [--json out.json]

Parts (b) and (c) of ``bokehfit bench`` (see :mod:`bokehfit.bench.fit` and
:mod:`bokehfit.bench.compare` for what is measured and how): fit error against
the fit time per photo with ``FitOptions.max_discs`` as the budget knob,
then ``compare`` on a 24-MP JPEG (``--quick``: the 2-photo set, budgets 2 and 6,
and a 4-MP JPEG), warm by stage and cold in a fresh process. The script prints
tables and asserts nothing; ``--json`` also writes the figures.
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import bokehfit
from bokehfit.bench.compare import compare_timing
from bokehfit.bench.fit import budget_sweep
from bokehfit.bench.report import compare_table, fit_table, markdown_table
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="2-photo fit set, budgets 2 and 6, a 4-MP photo")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    args = parser.parse_args()
    out = check_output_path(args.json, (".json",)) if args.json else None
    print(f"bokehfit {bokehfit.__version__}, Python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs")

    fits = budget_sweep(args.quick)
    compared = compare_timing(args.quick)
    result = {"fit": fits["rows"], "fit_set": fits["description"], "fit_misses": fits["misses"], "compare": compared}
    print("\n## Fit error against fit time (FitOptions.max_discs)\n")
    print(fits["description"] + "\n")
    print(markdown_table(*fit_table(result)))
    for budget, names in fits["misses"].items():
        print(f"wrong shape at max_discs={budget}: {', '.join(names)}")
    print(f"\n## compare on a {compared['megapixels']:.1f}-MP JPEG, seconds\n")
    print(markdown_table(*compare_table(result)))
    print(f"\nfound {compared['discs_found']} discs, fitted {compared['discs_fitted']}: {compared['aperture']}; "
          f"kernel {compared['kernel_method']} on {compared['device'].get('adapter') or 'the CPU'}; "
          f"cold process: import {compared['cold_import_s']:.2f} s, "
          f"start to exit {compared['cold_process_s']:.2f} s")
    if out:
        write_json(Path(out), {"bokehfit_version": bokehfit.__version__, "quick": args.quick, **result})
        print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
